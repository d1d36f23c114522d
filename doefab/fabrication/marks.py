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
  align to it); on layer 11, datatype m+1, a vernier (pitch p·(1 + 1/10) against the reference layer's pitch p
  scale) and a CD ladder of lines at 1, 1.5, 2 and 3 × the critical dimension. The chrome plate's reference
  vernier scale and ladder are on layer 11, datatype 0; its keys on layer 10, datatype 0.

Each further plate's key sites sit one step further in and its CD ladder one step further along, so a set of
more masks needs a larger die: :func:`check_mark_placement` refuses marks that fall off the die or into the clear
aperture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gdstk
import numpy as np

from doefab.diekey import die_outline

__all__ = ["MarkSpec", "chrome_polygons", "clear_fields", "mark_polygons", "key_site", "check_mark_placement",
           "mark_layout", "smallest_die_m", "CLEAR_MARGIN_NM"]

KEY_ARM_NM = 80_000
KEY_WIDTH_NM = 10_000
WINDOW_NM = 260_000
SITE_STEP_NM = 300_000
CLEAR_MARGIN_NM = 40_000  # the clear glass the chrome plate leaves round every mark's bounding box


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


def _rect(x0, y0, x1, y1, layer, datatype):
    return gdstk.rectangle((x0, y0), (x1, y1), layer=layer, datatype=datatype)


def key_site(spec: MarkSpec, plate: int) -> list[tuple[int, int]]:
    """Centres (nm) of plate ``plate``'s four key sites (plate 0 = chrome, 1..M = etch masks).

    Sites sit on the diagonal in each die corner, one SITE_STEP further in per plate.
    """
    c = spec.die_nm // 2 - 250_000 - plate * SITE_STEP_NM
    return [(sx * c, sy * c) for sx in (-1, 1) for sy in (-1, 1)]


def _cross(cx, cy, layer, datatype):
    a, w = KEY_ARM_NM, KEY_WIDTH_NM
    return [_rect(cx - a, cy - w // 2, cx + a, cy + w // 2, layer, datatype),
            _rect(cx - w // 2, cy - a, cx + w // 2, cy + a, layer, datatype)]


def clear_fields(marks: list, margin_nm: int) -> list:
    """The clear field around each mark (the die outline, layer 100, aside): its bounding box grown by
    ``margin_nm`` on every side (``MarkSpec.clear_margin_nm``), merged.
    The chrome plate leaves these bare, so its chrome keys, verniers and ladder stand in clear glass where an
    aligner and a microscope see them, and the etch plates' own crosses and ladders land on silica, not on chrome
    (which would mask their etch)."""
    m = margin_nm
    boxes = [gdstk.rectangle((x0 - m, y0 - m), (x1 + m, y1 + m))
             for (x0, y0), (x1, y1) in (poly.bounding_box() for poly in marks if poly.layer != 100)]
    return gdstk.boolean(boxes, [], "or") if boxes and m > 0 else []


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
    slit_w, gap, length = 20_000, 100_000, 600_000
    slits = [gdstk.rectangle((-slit_w // 2, r + gap), (slit_w // 2, r + gap + length)),
             gdstk.rectangle((-slit_w // 2, -r - gap - length), (slit_w // 2, -r - gap))]
    out = gdstk.boolean(die, [disk, *slits, *clear_fields(list(marks), spec.clear_margin_nm)], "not", layer=layer,
                        datatype=0)
    return out


def mark_polygons(spec: MarkSpec, align_to: dict[int, int]) -> list:
    """Keys, windows, verniers and CD ladders for the chrome plate (0) and etch plates 1..M.

    Args:
        align_to: etch plate → the plate it aligns to, one entry per etch plate (e.g. {1: 0, 2: 0, 3: 0, 4: 0}).
    """
    polys = []
    h = spec.die_nm // 2
    for plate in range(len(align_to) + 1):
        for cx, cy in key_site(spec, plate):
            polys += _cross(cx, cy, 10, plate)
        if plate > 0 and spec.windows:
            for cx, cy in key_site(spec, align_to[plate]):
                w = WINDOW_NM // 2
                polys.append(_rect(cx - w, cy - w, cx + w, cy + w, 10, plate))
        # vernier: 11 bars, reference pitch on plate 0, pitch × 1.1 on the etch plates, along the top edge
        pitch = 20_000 if plate == 0 else 22_000
        x_start = -h + 700_000  # every plate's vernier starts at the same x, so they overlay the reference
        y0 = h - 200_000 - (0 if plate == 0 else 40_000)
        for k in range(11):
            x = x_start + k * pitch
            polys.append(_rect(x, y0, x + 8_000, y0 + 40_000, 11, plate))
        # CD ladder along the bottom edge: line/space pairs at 1, 1.5, 2, 3 × CD
        x = -h + 700_000 + plate * 1_500_000 // 2
        for f in (1.0, 1.5, 2.0, 3.0):
            w = int(round(spec.cd_nm * f))
            for _ in range(5):
                polys.append(_rect(x, -h + 150_000, x + w, -h + 250_000, 11, plate))
                x += 2 * w
            x += 40_000
    # the dicing outline, keyed (``doefab.diekey``): the chamfers may cut a corner's keys, needed only until the
    # last etch
    polys.append(gdstk.Polygon(die_outline(spec.die_nm, spec.die_nm, spec.chamfer_nm, spec.coded_sign), 100, 0))
    return polys


def _misplaced(polys: list, spec: MarkSpec) -> tuple[int, int]:
    """(marks off the die, marks whose clear field reaches the clear aperture) among ``polys`` (the die outline
    aside)."""
    h, r, m = spec.die_nm // 2, spec.aperture_radius_nm, spec.clear_margin_nm
    off_die = into_aperture = 0
    for poly in polys:
        if poly.layer == 100:
            continue
        (x0, y0), (x1, y1) = poly.bounding_box()
        off_die += bool(x0 < -h or y0 < -h or x1 > h or y1 > h)
        # the clear field's nearest point to the aperture's centre
        dx, dy = max(x0 - m, -x1 - m, 0.0), max(y0 - m, -y1 - m, 0.0)
        into_aperture += bool(dx * dx + dy * dy < r * r)
    return off_die, into_aperture


def check_mark_placement(spec: MarkSpec, align_to: dict[int, int]) -> list:
    """The marks of :func:`mark_polygons`, every one (keys, windows, verniers, CD ladders) inside the die and clear
    of the aperture; else one error naming the smallest die (0.1 mm steps) that holds them."""
    from doefab.errors import DoefabError

    polys = mark_polygons(spec, align_to)
    off_die, into_aperture = _misplaced(polys, spec)
    if not off_die and not into_aperture:
        return polys
    need = next((die for die in range(spec.die_nm, 300_000_001, 100_000)
                 if not any(_misplaced(mark_polygons(MarkSpec(die, spec.aperture_radius_nm, spec.cd_nm), align_to),
                                       MarkSpec(die, spec.aperture_radius_nm, spec.cd_nm)))), None)
    fix = f"enlarge die_m to at least {need / 1e6:g} mm" if need else "use a smaller critical dimension"
    raise DoefabError(f"the alignment marks of {len(align_to) + 1} plates do not fit a {spec.die_nm / 1e6:g} mm die "
                      f"around a {2 * spec.aperture_radius_nm / 1e6:g} mm clear aperture ({off_die} off the die, "
                      f"{into_aperture} inside the aperture): {fix}")


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
        if not any(_misplaced(mark_polygons(spec, align_to), spec)):
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
