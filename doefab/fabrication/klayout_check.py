"""A second reader: KLayout reads a mask set's GDS (and OASIS) file on its own and checks every layer.

Each etch layer covers exactly its bit plane's pixel count and nothing outside the pixel grid; every other
(layer, datatype) equals the manifest's drawing (:func:`doefab.fabrication.layout_check.expected_layout`) within
the same tolerance as the gdstk check (the XOR, shrunk by half of it, is empty); no geometry lies on a layer the
set does not hold; the OASIS file, where written, equals the GDS file on every layer (XOR). Skipped, and
reported as such, where the klayout package is not installed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from doefab.errors import CheckFailed
from doefab.fabrication.bitplanes import bit_plane
from doefab.fabrication.layers import etch_layer
from doefab.fabrication.layout_check import DBU_NM, TOLERANCE_DBU, layer_name
from doefab.fabrication.process import mask_count

__all__ = ["klayout_check"]


def _load(kdb, folder: Path, name: str):
    lay = kdb.Layout()
    try:
        lay.read(str(folder / name))
    except RuntimeError as exc:
        raise CheckFailed(f"KLayout cannot read {folder / name} ({' '.join(str(exc).split())[:200]}): the file "
                          f"is corrupt or truncated; export the set again") from None
    if lay.top_cell() is None:
        raise CheckFailed(f"KLayout finds no top cell in {folder / name}: the file is empty or corrupt")
    if abs(lay.dbu * 1e3 - DBU_NM) > 1e-9:
        raise CheckFailed(f"KLayout: {folder / name} has a {lay.dbu * 1e3:g} nm database unit, a mask set's is "
                          f"{DBU_NM} nm; export the set again")
    return lay


def _regions(kdb, layout) -> dict:
    """(layer, datatype) → the merged region of the top cell's shapes (database units, 1 nm), non-empty only."""
    top, out = layout.top_cell(), {}
    for li in layout.layer_indexes():
        info = layout.get_info(li)
        region = kdb.Region(top.begin_shapes_rec(li))
        if not region.is_empty():
            out[(info.layer, info.datatype)] = region
    return out


def _at(region) -> str:
    c = region.bbox().center()
    return f"around ({c.x * DBU_NM / 1e3:.1f}, {c.y * DBU_NM / 1e3:.1f}) µm"


def klayout_check(folder: Path, man: dict, levels: np.ndarray, n_levels: int, expected: dict) -> dict:
    """KLayout's reading of the set in ``folder`` against the level map as drawn (``levels``) and the manifest's
    drawing of the other layers (``expected``: (layer, datatype) → vertices in nm); CheckFailed naming the layer."""
    try:
        import klayout.db as kdb
    except ImportError:
        return {"checked": False, "reason": "klayout not installed"}
    gds_layout = _load(kdb, folder, man["files"]["gds"])  # a Region of a layout's shapes reads them while it lives
    gds = _regions(kdb, gds_layout)
    etch = {(etch_layer(b), 0): b for b in range(mask_count(n_levels))}
    stray = sorted(set(gds) - set(expected) - set(etch))
    if stray:
        raise CheckFailed(f"KLayout: layer {stray[0][0]}/{stray[0][1]} holds geometry {_at(gds[stray[0]])} on a "
                          f"layer the manifest does not list: stray geometry; export the set again from its design")
    pitch_nm = int(round(man["pitch_m"] * 1e9))
    x0, y1 = (int(round(v * 1e9)) for v in man["origin_m"])
    grid = kdb.Box(x0, y1 - levels.shape[0] * pitch_nm, x0 + levels.shape[1] * pitch_nm, y1)
    out = {"checked": True, "layers": {}}
    for (lay, _), bit in etch.items():
        region = gds.get((lay, 0), kdb.Region())
        area_px = region.area() * DBU_NM**2 / pitch_nm**2
        expected_px = int(bit_plane(levels, bit, n_levels).sum())
        if abs(area_px - expected_px) > 1e-6:
            raise CheckFailed(f"KLayout: layer {lay} covers {area_px:.1f} pixels, the bit plane {expected_px}")
        if not region.is_empty() and not region.bbox().inside(grid):
            raise CheckFailed(f"KLayout: layer {lay} holds geometry outside the pixel grid "
                              f"{_at(region - kdb.Region(grid))}; export the set again from its design")
        out["layers"][str(lay)] = {"area_px": int(round(area_px))}
    for (lay, dt), polys in expected.items():
        ref = kdb.Region()
        for p in polys:
            ref.insert(kdb.Polygon([kdb.Point(int(x), int(y)) for x, y in p]))
        diff = (gds.get((lay, dt), kdb.Region()) ^ ref).sized(-(TOLERANCE_DBU // 2))
        if not diff.is_empty():
            raise CheckFailed(f"KLayout: layer {lay}/{dt} ({layer_name(lay, dt)}) differs from what manifest.json "
                              f"describes {_at(diff)} (tolerance {TOLERANCE_DBU * DBU_NM} nm); export the set again")
    out["marks_match_manifest"] = True
    if man["files"].get("oasis"):
        oas_layout = _load(kdb, folder, man["files"]["oasis"])
        oas = _regions(kdb, oas_layout)
        for key in sorted(set(gds) | set(oas)):
            xor = gds.get(key, kdb.Region()) ^ oas.get(key, kdb.Region())
            if not xor.is_empty():
                raise CheckFailed(f"KLayout: OASIS layer {key[0]}/{key[1]} differs from GDS (XOR area {xor.area()} "
                                  f"dbu², {_at(xor)}); export the set again")
        for entry in out["layers"].values():
            entry["oasis_identical"] = True
        out["oasis_identical"] = True
    return out
