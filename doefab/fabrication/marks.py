"""Chrome aperture, alignment keys, verniers, CD ladder and die outline (geometry via gdstk, in nm).

Scheme (all marks outside the clear aperture, in the four die corners):
- The chrome plate (layer 5, process step 1) is written first. It leaves chrome everywhere outside the
  clear aperture (the baffle), with clear slits on the y axis above and below the aperture marking the
  split line (x = 0), and chrome alignment crosses ("keys") at the four key sites.
- Every etch plate m carries (layer 10, datatype m+1) a clear window over the key sites of the layer it
  aligns to, plus its own cross at its own key site (so a later mask could align to it); on layer 11,
  datatype m+1, a vernier (pitch p·(1 + 1/10) against the reference layer's pitch p scale) and a CD ladder
  of lines at 1, 1.5, 2 and 3 × the critical dimension. The chrome plate's reference vernier scale and
  ladder are on layer 11, datatype 0; its keys on layer 10, datatype 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import gdstk

__all__ = ["MarkSpec", "chrome_polygons", "mark_polygons", "key_site"]

KEY_ARM_NM = 80_000
KEY_WIDTH_NM = 10_000
WINDOW_NM = 260_000
SITE_STEP_NM = 300_000


@dataclass(frozen=True)
class MarkSpec:
    """Geometry inputs of the marks (nanometres)."""

    die_nm: int
    aperture_radius_nm: int
    cd_nm: int


def _rect(x0, y0, x1, y1, layer, datatype):
    return gdstk.rectangle((x0, y0), (x1, y1), layer=layer, datatype=datatype)


def key_site(spec: MarkSpec, plate: int) -> list[tuple[int, int]]:
    """Centres (nm) of plate ``plate``'s four key sites (plate 0 = chrome, 1..4 = etch masks).

    Sites sit on the diagonal in each die corner, one SITE_STEP further in per plate.
    """
    c = spec.die_nm // 2 - 250_000 - plate * SITE_STEP_NM
    return [(sx * c, sy * c) for sx in (-1, 1) for sy in (-1, 1)]


def _cross(cx, cy, layer, datatype):
    a, w = KEY_ARM_NM, KEY_WIDTH_NM
    return [_rect(cx - a, cy - w // 2, cx + a, cy + w // 2, layer, datatype),
            _rect(cx - w // 2, cy - a, cx + w // 2, cy + a, layer, datatype)]


def chrome_polygons(spec: MarkSpec, layer: int = 5, circle_tolerance_nm: float = 5.0) -> list:
    """Chrome that stays on the die: the die minus the clear aperture, minus the split-line slits.

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
    out = gdstk.boolean(die, [disk, *slits], "not", layer=layer, datatype=0)
    return out


def mark_polygons(spec: MarkSpec, align_to: dict[int, int]) -> list:
    """Keys, windows, verniers and CD ladders for the chrome plate (0) and etch plates 1..4.

    Args:
        align_to: plate → the plate it aligns to (e.g. {1: 0, 2: 0, 3: 0, 4: 0}).
    """
    polys = []
    h = spec.die_nm // 2
    for plate in range(5):
        for cx, cy in key_site(spec, plate):
            polys += _cross(cx, cy, 10, plate)
        if plate > 0:
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
    polys.append(_rect(-h, -h, h, h, 100, 0))
    return polys
