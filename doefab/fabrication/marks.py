"""Chrome aperture, alignment keys, verniers, CD ladder and die outline (geometry via gdstk, in nm).

Scheme (all marks outside the clear aperture, in the four die corners):
- The chrome plate (layer 5, process step 1) is written first. It leaves chrome everywhere outside the
  clear aperture (the baffle), with clear slits on the y axis above and below the aperture marking the
  split line (x = 0), a clear field around every mark of every plate (``clear_fields``), and chrome alignment
  crosses ("keys") at the four key sites inside theirs.
- The die outline (layer 100) is the dicing outline, keyed for the holder (``doefab.diekey``: two unequal
  chamfers on the coded half's corners).
- Every etch plate m (m = 0..M−1, one per binary mask) carries (layer 10, datatype m+1) a clear window over the key
  sites of the layer it aligns to (for positive resist, whose etch plates are dark field; a clear-field plate for
  negative resist is clear there without one), plus its own cross at its own key site (so a later mask could
  align to it); on layer 11, datatype m+1, its CD ladder of lines at 1, 1.5, 2 and 3 × the critical dimension,
  and its own x vernier (top edge) and y vernier (left edge), each a 21-bar scale of pitch p − 0.25 µm against a
  reference scale of pitch p drawn on the plate it aligns to (``_vernier``). The chrome plate's ladder is on
  layer 11, datatype 0; its keys on layer 10, datatype 0. Every mark is at least the CD wide.

Each further plate's key sites sit one step further in, its ladder and vernier sites one step further along, so a
set of more masks needs a larger die: :func:`check_mark_placement` refuses marks that fall off the die, into the
clear aperture or onto one another. A set of format 1 or 2 is drawn as it was (``MarkSpec.legacy``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gdstk
import numpy as np

from doefab.diekey import die_outline

__all__ = ["MarkSpec", "chrome_polygons", "clear_fields", "mark_polygons", "key_site", "check_mark_placement",
           "mark_layout", "smallest_die_m", "CLEAR_MARGIN_NM", "vernier_scale", "vernier_sites", "vernier_record",
           "key_width", "nm_to_m", "clear_boxes", "split_slits"]

KEY_ARM_NM = 80_000
KEY_WIDTH_NM = 10_000
WINDOW_NM = 260_000
SITE_STEP_NM = 300_000
CLEAR_MARGIN_NM = 40_000  # the clear glass the chrome plate leaves round every mark's bounding box
VERNIER_BARS = 21  # bars per scale, k = −10..10
VERNIER_STEP_NM = 250  # the reading step: the vernier scale's pitch is the reference's less this
VERNIER_BAR_NM = 40_000  # bar length across the scale (the zero bars VERNIER_ZERO_EXTRA_NM longer)
VERNIER_ZERO_EXTRA_NM = 20_000
VERNIER_LINE_NM = 200_000  # the two scales meet this far inside the die edge
VERNIER_START_NM = 700_000  # the first site's scales start this far from the top-left corner
VERNIER_GAP_NM = 200_000  # between two plates' sites


@dataclass(frozen=True)
class MarkSpec:
    """Geometry inputs of the marks (nanometres)."""

    die_nm: int
    aperture_radius_nm: int
    cd_nm: int
    chamfer_nm: int = 0  # the die key's larger chamfer (``doefab.diekey``); 0: a square outline
    coded_sign: int = 1  # the coded half's side of the layout: x > 0 (1, pattern toward the lens) or x < 0 (−1)
    clear_margin_nm: int = CLEAR_MARGIN_NM  # clear glass the chrome plate leaves round every mark (0: none)
    # whether the etch plates' windows are drawn: a dark-field plate (positive resist) is clear only inside its
    # polygons, so a window is drawn over the keys; a clear-field plate (negative resist) is clear outside them,
    # and a drawn window would be chrome over the keys
    windows: bool = True
    # a set of format 1 or 2 as it was drawn: one 11-bar vernier per plate on a shared reference at the top edge,
    # 10 µm keys and 20 µm slits and 750 µm between ladders whatever the CD, placed clear of the aperture only
    legacy: bool = False


def _rect(x0, y0, x1, y1, layer, datatype):
    return gdstk.rectangle((x0, y0), (x1, y1), layer=layer, datatype=datatype)


def key_site(spec: MarkSpec, plate: int) -> list[tuple[int, int]]:
    """Centres (nm) of plate ``plate``'s four key sites (plate 0 = chrome, 1..M = etch masks).

    Sites sit on the diagonal in each die corner, one SITE_STEP further in per plate.
    """
    c = spec.die_nm // 2 - 250_000 - plate * SITE_STEP_NM
    return [(sx * c, sy * c) for sx in (-1, 1) for sy in (-1, 1)]


def _cross(cx, cy, layer, datatype, w=KEY_WIDTH_NM, legacy=False):
    """A key cross as one 12-vertex polygon (two overlapping rectangles would be exposed twice where they cross on a
    writer that does not merge shapes); a set of format 1 or 2 drew the two rectangles (``legacy``)."""
    a, b = KEY_ARM_NM, w // 2
    if legacy:
        return [_rect(cx - a, cy - b, cx + a, cy + b, layer, datatype), _rect(cx - b, cy - a, cx + b, cy + a, layer,
                                                                                datatype)]
    pts = [(a, b), (b, b), (b, a), (-b, a), (-b, b), (-a, b), (-a, -b), (-b, -b), (-b, -a), (b, -a), (b, -b), (a, -b)]
    return [gdstk.Polygon([(cx + x, cy + y) for x, y in pts], layer, datatype)]


def clear_fields(marks: list, margin_nm: int) -> list:
    """The clear field around each mark (the die outline, layer 100, aside): its bounding box grown by
    ``margin_nm`` on every side (``MarkSpec.clear_margin_nm``), merged.
    The chrome plate leaves these bare, so its chrome keys, verniers and ladder stand in clear glass where an
    aligner and a microscope see them, and the etch plates' own crosses and ladders land on silica, not on chrome
    (which would mask their etch)."""
    boxes = clear_boxes(marks, margin_nm)
    return gdstk.boolean(boxes, [], "or") if boxes and margin_nm > 0 else []


def clear_boxes(marks: list, margin_nm: int) -> list:
    """Each mark's bounding box grown by ``margin_nm`` (the die outline aside), unmerged: the rectangles
    :func:`clear_fields` merges."""
    m = margin_nm
    return [gdstk.rectangle((x0 - m, y0 - m), (x1 + m, y1 + m))
            for (x0, y0), (x1, y1) in (poly.bounding_box() for poly in marks if poly.layer != 100)]


def split_slits(spec: MarkSpec) -> list:
    """The chrome plate's two clear slits on the y axis above and below the clear aperture, marking the split line."""
    r, w, gap, length = spec.aperture_radius_nm, key_width(spec), 100_000, 600_000
    return [gdstk.rectangle((-w, r + gap), (w, r + gap + length)),
            gdstk.rectangle((-w, -r - gap - length), (w, -r - gap))]


def chrome_polygons(spec: MarkSpec, layer: int = 5, circle_tolerance_nm: float = 5.0, marks: list = ()) -> list:
    """Chrome that stays on the die: the die minus the clear aperture, minus the split-line slits, minus the clear
    field around each of ``marks`` (:func:`clear_fields`, ``spec.clear_margin_nm``; the chrome plate's marks are
    chrome inside it).

    The disk is a polygon whose chords deviate from the circle by at most ``circle_tolerance_nm``;
    the hole is joined to the outer boundary the GDSII way (gdstk's boolean links holes with a cut).
    """
    h = spec.die_nm // 2
    r = spec.aperture_radius_nm
    die = gdstk.rectangle((-h, -h), (h, h))
    disk = gdstk.ellipse((0, 0), r, tolerance=circle_tolerance_nm)
    bare = [disk, *split_slits(spec), *clear_fields(list(marks), spec.clear_margin_nm)]
    return gdstk.boolean(die, bare, "not", layer=layer, datatype=0)


def mark_polygons(spec: MarkSpec, align_to: dict[int, int]) -> list:
    """Keys, windows, verniers and CD ladders for the chrome plate (0) and etch plates 1..M, and the die outline.

    Args:
        align_to: etch plate → the plate it aligns to, one entry per etch plate (e.g. {1: 0, 2: 0, 3: 0, 4: 0}).
    """
    polys = []
    for plate in range(len(align_to) + 1):
        for cx, cy in key_site(spec, plate):
            polys += _cross(cx, cy, 10, plate, key_width(spec), spec.legacy)
        if plate > 0 and spec.windows:
            for cx, cy in key_site(spec, align_to[plate]):
                w = WINDOW_NM // 2
                polys.append(_rect(cx - w, cy - w, cx + w, cy + w, 10, plate))
        polys += _ladder(spec, plate)
        if spec.legacy:
            polys += _legacy_vernier(spec, plate)
    if not spec.legacy:
        for plate, ref in sorted(align_to.items()):
            polys += _vernier(spec, plate, ref, "x") + _vernier(spec, plate, ref, "y")
    # the dicing outline, keyed (``doefab.diekey``): the chamfers may cut a corner's keys, needed only until the
    # last etch
    polys.append(gdstk.Polygon(die_outline(spec.die_nm, spec.die_nm, spec.chamfer_nm, spec.coded_sign), 100, 0))
    return polys


def key_width(spec: MarkSpec) -> int:
    """The width (nm) of a key cross's arms and the split-line slits' half width floor: 10 µm, or the CD where that
    is wider (a set of format 1 or 2: 10 µm whatever the CD)."""
    return KEY_WIDTH_NM if spec.legacy else max(KEY_WIDTH_NM, spec.cd_nm)


def vernier_scale(cd_nm: int) -> tuple[int, int]:
    """(bar width, reference pitch) of the verniers in nm: bars as wide as the CD (at least 4 µm), the pitch
    20 µm or four bars, whichever is larger. Example: ``vernier_scale(5400) == (5400, 21600)``."""
    bar = max(int(cd_nm), 4_000)
    return bar, max(20_000, 4 * bar)


def vernier_sites(spec: MarkSpec, plate: int) -> tuple[int, int]:
    """(x of the x vernier's zero bars on the top edge, y of the y vernier's zero bars on the left edge), nm, of
    etch plate ``plate`` (1..M): one pair of sites per plate, side by side from the top-left corner."""
    bar, pitch = vernier_scale(spec.cd_nm)
    half = (VERNIER_BARS // 2) * pitch + bar
    off = VERNIER_START_NM + half + (plate - 1) * (2 * half + VERNIER_GAP_NM)
    h = spec.die_nm // 2
    return -h + off, h - off


def _vernier(spec: MarkSpec, plate: int, ref: int, axis: str) -> list:
    """Plate ``plate``'s vernier along ``axis`` against plate ``ref``'s reference scale: ``VERNIER_BARS`` bars at
    the reference pitch on ``ref`` (toward the die edge) and at that pitch less ``VERNIER_STEP_NM`` on ``plate``
    (inward), meeting on a line ``VERNIER_LINE_NM`` inside the edge; the middle bars (k = 0) are longer. Bar k of
    the two scales lines up when ``plate`` sits k · ``VERNIER_STEP_NM`` from ``ref`` along +``axis``."""
    bar, pitch = vernier_scale(spec.cd_nm)
    h = spec.die_nm // 2
    zx, zy = vernier_sites(spec, plate)
    out = []
    for k in range(-(VERNIER_BARS // 2), VERNIER_BARS // 2 + 1):
        length = VERNIER_BAR_NM + (VERNIER_ZERO_EXTRA_NM if k == 0 else 0)
        for dt, at, inward in ((ref, k * pitch, False), (plate, k * (pitch - VERNIER_STEP_NM), True)):
            lo = (0, length) if not inward else (-length, 0)  # across the bars, from the meeting line
            if axis == "x":  # vertical bars along the top edge; the reference toward the edge (+y)
                c, line = zx + at, h - VERNIER_LINE_NM
                out.append(_rect(c - bar // 2, line + lo[0], c - bar // 2 + bar, line + lo[1], 11, dt))
            else:  # horizontal bars along the left edge; the reference toward the edge (−x)
                c, line = zy + at, -h + VERNIER_LINE_NM
                out.append(_rect(line - lo[1], c - bar // 2, line - lo[0], c - bar // 2 + bar, 11, dt))
    return out


def vernier_record(die_nm: int, cd_nm: int, align_to: dict[int, int]) -> dict:
    """The mask manifest's ``verniers``: the scales' geometry, each etch plate's two sites (metres: the zero bars'
    position along the edge and the scales' meeting line) and how to read them."""
    bar, pitch = vernier_scale(cd_nm)
    spec = MarkSpec(die_nm, 0, cd_nm)
    return {
        "bars": VERNIER_BARS, "bar_width_nm": bar, "reference_pitch_nm": pitch,
        "vernier_pitch_nm": pitch - VERNIER_STEP_NM, "reading_step_nm": VERNIER_STEP_NM,
        "range_nm": (VERNIER_BARS // 2) * VERNIER_STEP_NM,
        "sites_m": {str(p): {"x": [nm_to_m((x := vernier_sites(spec, p))[0]), nm_to_m(die_nm // 2 - VERNIER_LINE_NM)],
                             "y": [nm_to_m(-(die_nm // 2) + VERNIER_LINE_NM), nm_to_m(x[1])], "reference_plate": ref}
                    for p, ref in sorted(align_to.items())},
        "reads": ("each etch plate has an x vernier on the top edge and a y vernier on the left edge (layer 11, its "
                  "plate number as datatype) against a reference scale on the plate it aligns to (layer 11, that "
                  "plate's datatype), the two scales meeting on a line at the site; the longer middle bars are "
                  f"k = 0. Where bar k (counted from them, + toward +x or +y) of the two scales lines up, the plate "
                  f"sits k × {VERNIER_STEP_NM / 1000:g} µm from its reference along +x or +y"),
    }


def nm_to_m(nm: int) -> float:
    """Nanometres as metres for a manifest, without float noise (0.0058, not 0.0058000000000000005)."""
    return round(nm * 1e-9, 12)


def _legacy_vernier(spec: MarkSpec, plate: int) -> list:
    """A set of format 1 or 2 as drawn: 11 bars along the top edge, the reference pitch on plate 0 and 1.1 × it on
    every etch plate, all starting at the same x."""
    h = spec.die_nm // 2
    pitch = 20_000 if plate == 0 else 22_000
    y0 = h - 200_000 - (0 if plate == 0 else 40_000)
    return [_rect(-h + 700_000 + k * pitch, y0, -h + 700_000 + k * pitch + 8_000, y0 + 40_000, 11, plate)
            for k in range(11)]


def _ladder(spec: MarkSpec, plate: int) -> list:
    """Plate ``plate``'s CD ladder along the bottom edge: five line/space pairs at 1, 1.5, 2 and 3 × the CD, each
    plate's one ``ladder_step`` further along."""
    h = spec.die_nm // 2
    step = 750_000 if spec.legacy else max(750_000, 75 * spec.cd_nm + 260_000)  # a ladder is 75 CD + 160 µm long
    x, out = -h + 700_000 + plate * step, []
    for f in (1.0, 1.5, 2.0, 3.0):
        w = int(round(spec.cd_nm * f))
        for _ in range(5):
            out.append(_rect(x, -h + 150_000, x + w, -h + 250_000, 11, plate))
            x += 2 * w
        x += 40_000
    return out


def _misplaced(polys: list, spec: MarkSpec, align_to: dict[int, int]) -> tuple[int, int, int]:
    """(marks off the die, marks whose clear field reaches the clear aperture, overlaps between marks:
    ``_overlaps``) among ``polys`` (the die outline aside)."""
    h, r, m = spec.die_nm // 2, spec.aperture_radius_nm, spec.clear_margin_nm
    off_die = into_pattern = 0
    for poly in polys:
        if poly.layer == 100:
            continue
        (x0, y0), (x1, y1) = poly.bounding_box()
        off_die += bool(x0 < -h or y0 < -h or x1 > h or y1 > h)
        # the clear field's nearest point to the aperture's centre
        dx, dy = max(x0 - m, -x1 - m, 0.0), max(y0 - m, -y1 - m, 0.0)
        into_pattern += bool(dx * dx + dy * dy < r * r)
    return off_die, into_pattern, (0 if spec.legacy else _overlaps(polys, align_to))


def _overlaps(polys: list, align_to: dict[int, int]) -> int:
    """Overlaps between marks (a ladder or vernier drawn over a key, a window or another scale cannot be read):
    pairs of plates whose marks overlap, and plates whose own marks do. A window over the keys of the plate it
    aligns to, and windows over one another, are meant."""
    marks, windows = {}, {}
    for p in polys:
        if p.layer == 100:
            continue
        (x0, y0), (x1, y1) = p.bounding_box()
        window = p.layer == 10 and len(p.points) == 4 and round(x1 - x0) == round(y1 - y0) == WINDOW_NM
        (windows if window else marks).setdefault(p.datatype, []).append(p)

    def area(polys_a, polys_b=None) -> float:
        both = gdstk.boolean(polys_a, polys_b or [], "and" if polys_b is not None else "or")
        return sum(q.area() for q in both)
    plates = sorted(marks)
    n = sum(area(marks[a], marks[b]) > 0 for i, a in enumerate(plates) for b in plates[i + 1:])
    n += sum(sum(q.area() for q in marks[a]) > area(marks[a]) * (1 + 1e-9) for a in plates)
    for p, ws in windows.items():
        others = [m for q, ms in marks.items() for m in ms if not (q == align_to[p] and m.layer == 10)]
        n += bool(others) and area(ws, others) > 0
    return n


def check_mark_placement(spec: MarkSpec, align_to: dict[int, int]) -> list:
    """The marks of :func:`mark_polygons`, every one (keys, windows, verniers, CD ladders) inside the die and clear
    of the aperture; else one error naming the smallest die (0.1 mm steps) that holds them."""
    from dataclasses import replace

    from doefab.errors import DoefabError

    polys = mark_polygons(spec, align_to)
    off_die, into_pattern, overlaps = _misplaced(polys, spec, align_to)
    if not off_die and not into_pattern and not overlaps:
        return polys
    need = next((die for die in range(spec.die_nm, 300_000_001, 100_000)
                 if not any(_misplaced(mark_polygons(replace(spec, die_nm=die), align_to),
                                       replace(spec, die_nm=die), align_to))), None)
    fix = f"enlarge die_m to at least {need / 1e6:g} mm" if need else "use a smaller critical dimension"
    raise DoefabError(f"the alignment marks of {len(align_to) + 1} plates do not fit a {spec.die_nm / 1e6:g} mm die "
                      f"around a {2 * spec.aperture_radius_nm / 1e6:g} mm clear aperture ({off_die} off the die, "
                      f"{into_pattern} inside the aperture, {overlaps} overlapping): {fix}")


def smallest_die_m(aperture_diameter_m: float, extent_m: float, cd_m: float, n_masks: int,
                   floor_m: float = 12e-3) -> float:
    """The smallest square die in whole millimetres, at least ``floor_m`` (12 mm: the prototype's), that holds a
    pattern ``extent_m`` wide with a 1 mm margin and every mark of ``n_masks`` plates aligned to the chrome keys
    clear of the aperture (m). Example: ``smallest_die_m(8.64e-3, 8.64e-3, 5.4e-6, 4) == 0.012``."""
    radius_nm, cd_nm = int(round(aperture_diameter_m / 2 * 1e9)), max(1, int(round(cd_m * 1e9)))
    align_to = {plate: 0 for plate in range(1, n_masks + 1)}
    die_mm = max(math.ceil(floor_m * 1e3 - 1e-9), math.ceil(extent_m * 1e3 + 2 - 1e-9))
    while die_mm < 300:
        spec = MarkSpec(die_mm * 1_000_000, radius_nm, cd_nm)
        if not any(_misplaced(mark_polygons(spec, align_to), spec, align_to)):
            return die_mm * 1e-3
        die_mm += 1
    return die_mm * 1e-3


def mark_layout(spec: MarkSpec, align_to: dict[int, int], vertex_cap: int,
                chrome_layer: int = 5) -> list[tuple[np.ndarray, int, int]]:
    """Every polygon besides the etch layers as the layout holds it: the chrome plate and the marks of
    :func:`check_mark_placement`, each as (integer vertices in nm, layer, datatype), a polygon over
    ``vertex_cap`` vertices fractured into pieces within it (the export writes these; verification redraws
    them from the manifest and compares)."""
    out = []
    marks = check_mark_placement(spec, align_to)
    for big in chrome_polygons(spec, chrome_layer, marks=marks) + marks:
        pieces = [big] if len(big.points) <= vertex_cap else big.fracture(max_points=vertex_cap, precision=1e-3)
        out += [(np.rint(poly.points).astype(np.int64), big.layer, big.datatype) for poly in pieces]
    return out
