"""Read a mask set back and prove it: every etch layer, rasterised from the file, equals its bit plane.

Checks (all in the report; any failure fails the export or ``doefab masks --verify``):
every etch depth, the level step and the level → height table re-derived from the manifest's material and
design wavelength (``manifest.depth_problems``), README.txt equal to what the manifest says, zero mismatched
pixels per etch layer (gdstk reader; KLayout's too where installed), Σ 2^m·mask_m
reproduces the level map, every polygon within the vertex cap and on the design grid, every plate's marks
present, the level map's checksum equals the manifest's, OASIS geometry identical to GDS (where written).
A width/space report at the critical dimension lists features below it and isolated single pixels.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from doefab.errors import CheckFailed, DoefabError
from doefab.fabrication.bitplanes import bit_plane, rasterize_manhattan
from doefab.fabrication.levels import levels_sha256
from doefab.fabrication.layers import CHROME_LAYER, KEY_LAYER, OUTLINE_LAYER, VERNIER_LAYER, etch_layer
from doefab.fabrication.manifest import depth_problems, fab_readme, manifest_levels
from doefab.fabrication.process import mask_count

__all__ = ["verify_mask_set", "read_gds_layers", "width_space_report", "preview_names"]


class LayerPolygons:
    """All polygons of one (layer, datatype): concatenated int64 vertices (database units) and counts."""

    def __init__(self, points: np.ndarray, counts: np.ndarray):
        self.points, self.counts = points, counts

    def __len__(self) -> int:
        return len(self.counts)

    @property
    def max_vertices(self) -> int:
        return int(self.counts.max(initial=0))


def read_gds_layers(path: Path, only: set | None = None) -> dict[tuple[int, int], LayerPolygons]:
    """Polygons per (layer, datatype) read with gdstk (``only``: read just these (layer, datatype) pairs)."""
    import gdstk

    lib = gdstk.read_gds(str(path), filter=only)
    tops = lib.top_level()
    if len(tops) != 1:
        raise CheckFailed(f"{path} must hold exactly one top cell, found {len(tops)}")
    cell = tops[0]
    scale = lib.unit / lib.precision
    out = {}
    for layer, datatype in sorted(lib.layers_and_datatypes()):
        polys = cell.get_polygons(layer=layer, datatype=datatype)
        if not polys:
            continue
        pts = [p.points for p in polys]
        counts = np.array([len(q) for q in pts], np.int64)
        out[(int(layer), int(datatype))] = LayerPolygons(np.rint(np.concatenate(pts) * scale).astype(np.int64),
                                                         counts)
    return out


def _to_pixels(polys: LayerPolygons, origin_nm: tuple[int, int], pitch_nm: int):
    pts = polys.points
    idx = np.repeat(np.arange(len(polys.counts)), polys.counts)
    col = pts[:, 0] - origin_nm[0]
    row = origin_nm[1] - pts[:, 1]
    if np.any(col % pitch_nm) or np.any(row % pitch_nm):
        raise CheckFailed("a polygon vertex lies off the design grid (not an integer number of pixels)")
    return np.stack([col // pitch_nm, row // pitch_nm], axis=1), idx


def width_space_report(plane: np.ndarray, cd_px: int, pitch_m: float, origin_m: tuple[float, float],
                       max_locations: int = 10) -> dict:
    """Features (etched) and spaces (unetched) narrower than ``cd_px`` pixels, and isolated single pixels."""

    def narrow(mask):
        bad = np.zeros_like(mask)
        for axis in (0, 1):
            m = np.moveaxis(mask, axis, 1)
            padded = np.pad(m, ((0, 0), (1, 1)))
            d = np.diff(padded.astype(np.int8), axis=1)
            r, s = np.nonzero(d == 1)
            _, e = np.nonzero(d == -1)
            short = (e - s) < cd_px
            b = np.zeros_like(m)
            for rr, ss, ee in zip(r[short], s[short], e[short]):
                b[rr, ss:ee] = True
            bad |= np.moveaxis(b, 1, axis)
        return bad

    p = plane.astype(bool)
    pad = np.pad(p, 1, constant_values=False)
    same = (pad[:-2, 1:-1] == p).astype(np.int8) + (pad[2:, 1:-1] == p) + (pad[1:-1, :-2] == p) + (pad[1:-1, 2:] == p)
    isolated = p & (same == 0)
    rows, cols = np.nonzero(isolated)
    locs = [[round(origin_m[0] * 1e6 + (c + 0.5) * pitch_m * 1e6, 3), round(origin_m[1] * 1e6 - (r + 0.5) * pitch_m * 1e6, 3)]
            for r, c in zip(rows[:max_locations], cols[:max_locations])]
    out = {"isolated_single_pixels": int(isolated.sum()), "isolated_locations_um": locs}
    if cd_px > 1:
        out["features_below_cd_px"] = int(narrow(p).sum())
        out["spaces_below_cd_px"] = int(narrow(~p).sum())
    else:
        out["features_below_cd_px"] = 0
        out["spaces_below_cd_px"] = 0
    return out


def preview_names(n_masks: int) -> tuple[str, ...]:
    """The preview images a finished set of ``n_masks`` etch layers holds."""
    return tuple(f"preview_layer{etch_layer(b)}.png" for b in range(n_masks)) + ("preview_composite.png",)


def _check_manifest(man, mpath: Path) -> None:
    """The manifest fields verification relies on, checked for type and range."""
    def need(ok: bool, key: str, what: str):
        if not ok:
            raise CheckFailed(f"{mpath}: {key} {what}")

    need(isinstance(man, dict), "(top level)", "must be a JSON object")
    need(str(man.get("format", "")).startswith("doefab mask set"), "format", "is not 'doefab mask set 1'")
    p = man.get("pitch_m")
    need(isinstance(p, (int, float)) and 1e-7 <= p <= 1e-3, "pitch_m", f"= {p!r} is not a pitch in metres (1e-7–1e-3)")
    sh = man.get("shape")
    need(isinstance(sh, list) and len(sh) == 2 and all(isinstance(x, int) and 0 < x <= 100_000 for x in sh), "shape",
         f"= {sh!r} is not [rows, columns]")
    o = man.get("origin_m")
    need(isinstance(o, list) and len(o) == 2 and all(isinstance(x, (int, float)) and abs(x) < 1 for x in o),
         "origin_m", f"= {o!r} is not an (x, y) position in metres")
    vc = man.get("vertex_cap")
    need(isinstance(vc, int) and 5 <= vc <= 8190, "vertex_cap", f"= {vc!r} is not in 5..8190")
    need(isinstance(man.get("levels_sha256"), str), "levels_sha256", "is missing")
    need(isinstance(man.get("mirrored_x", False), bool), "mirrored_x", "must be true or false")
    files = man.get("files")
    need(isinstance(files, dict) and isinstance(files.get("gds"), str), "files", "must name the GDS file")
    for v in files.values():
        need(isinstance(v, str) and "/" not in v and "\\" not in v and not v.startswith("."), "files",
             f"holds {v!r}, not a plain file name in the set")


def _check_depths(man: dict, mpath: Path, design_json: Path) -> None:
    """Every depth the fab reads, re-derived from the material and design wavelength (CheckFailed naming each
    inconsistent field)."""
    problems = depth_problems(man, design_json)
    if problems:
        raise CheckFailed(f"{mpath}: {len(problems)} field(s) disagree with the depths re-derived from the "
                          f"manifest's material and design wavelength: {'; '.join(problems)} — the fab would etch "
                          f"these depths; export the set again from its design")


def _check_readme(man: dict, path: Path) -> None:
    try:
        want = fab_readme(man)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CheckFailed(f"{path.parent / 'manifest.json'} lacks what README.txt states ({exc!r})") from None
    try:
        same = path.read_text() == want
    except (OSError, UnicodeDecodeError):
        same = False
    if not same:
        raise CheckFailed(f"{path} differs from what manifest.json says (edited by hand?): the fab reads both; "
                          f"export the set again")


def verify_mask_set(folder: str | Path, levels: np.ndarray | None = None, use_klayout: bool = True,
                    complete: bool = True) -> dict:
    """Verify the mask set in ``folder`` (manifest.json + GDS [+ OASIS]); raise CheckFailed on any failure.

    ``complete``: also require every file a finished set holds (README.txt, report.json, previews, the
    design's level map); the export itself verifies its staging folder before those are written.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DoefabError(f"{folder} is not a folder: give the mask-set folder doefab masks wrote")
    mpath = folder / "manifest.json"
    if not mpath.is_file():
        raise DoefabError(f"{folder} is not a mask set (manifest.json is missing): give the folder doefab masks wrote")
    try:
        man = json.loads(mpath.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise CheckFailed(f"{mpath} is not valid JSON ({exc}): the set is corrupt; export it again") from None
    _check_manifest(man, mpath)
    _check_depths(man, mpath, folder / "design" / "design.json")
    n_levels = manifest_levels(man)  # checked by _check_depths
    n_masks = mask_count(n_levels)
    if complete:
        wanted = list(man["files"].values()) + ["README.txt", "report.json", "design/levels.npy",
                                                *preview_names(n_masks)]
        missing = [f for f in wanted if not (folder / f).is_file()]
        if missing:
            raise CheckFailed(f"{folder} is incomplete: {', '.join(missing)} missing (an interrupted export or a "
                              f"copied-in-part set); export it again with doefab masks --force")
        _check_readme(man, folder / "README.txt")
    if levels is None:
        lpath = folder / "design" / "levels.npy"
        if not lpath.is_file():
            raise CheckFailed(f"{lpath} is missing: the mask set must keep the level map it came from")
        try:
            levels = np.load(lpath, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise CheckFailed(f"{lpath} is not a readable .npy array ({exc})") from None
    if getattr(levels, "shape", None) != tuple(man["shape"]):
        raise CheckFailed(f"the level map's shape {getattr(levels, 'shape', None)} differs from manifest.json's "
                          f"shape {man['shape']}")
    if levels_sha256(levels) != man["levels_sha256"]:
        raise CheckFailed("the level map's SHA-256 differs from manifest.json's levels_sha256: wrong or changed design")
    if np.asarray(levels).max(initial=0) >= n_levels:
        raise CheckFailed(f"the level map holds level {int(np.asarray(levels).max())} but manifest.json says n_levels = "
                          f"{n_levels}: the set is inconsistent; export it again from its design")
    pitch_nm = int(round(man["pitch_m"] * 1e9))
    origin_nm = (int(round(man["origin_m"][0] * 1e9)), int(round(man["origin_m"][1] * 1e9)))
    shape = tuple(man["shape"])
    # compare against the level map as drawn (mirrored in x when the pattern faces the lens)
    levels = np.asarray(levels, np.uint8)
    if man.get("mirrored_x", False):
        levels = np.ascontiguousarray(levels[:, ::-1])
    gds = folder / man["files"]["gds"]
    mark_keys = {(CHROME_LAYER, 0), (OUTLINE_LAYER, 0)} | {(k, p) for k in (KEY_LAYER, VERNIER_LAYER)
                                                           for p in range(n_masks + 1)}
    layers = _read(gds, mark_keys)  # chrome, marks and outline: small
    report: dict = {"gds": gds.name, "layers": {}, "ok": True}
    cap = int(man["vertex_cap"])
    etch_sum = np.zeros(shape, np.uint8)
    for bit in range(n_masks):
        lay = etch_layer(bit)
        # one etch layer at a time keeps the peak memory to one layer's polygons
        polys = _read(gds, {(lay, 0)}).get(
            (lay, 0), LayerPolygons(np.zeros((0, 2), np.int64), np.zeros(0, np.int64)))
        if len(polys):
            pix, idx = _to_pixels(polys, origin_nm, pitch_nm)
            wind = rasterize_manhattan(pix, idx, shape)
        else:
            wind = np.zeros(shape, np.int32)
        if np.any(wind < 0) or np.any(wind > 1):
            raise CheckFailed(f"layer {lay}: overlapping or inverted polygons (winding number {wind.min()}..{wind.max()})")
        got = wind.astype(bool)
        del wind
        mism = int(np.count_nonzero(got != bit_plane(levels, bit, n_levels)))
        maxv = polys.max_vertices
        report["layers"][str(lay)] = {"polygons": len(polys), "vertices": int(polys.counts.sum()),
                                      "max_vertices": maxv, "mismatched_pixels_gdstk": mism}
        if mism:
            raise CheckFailed(f"layer {lay}: {mism} pixels differ between the GDS and the design's bit plane {bit}")
        if maxv > cap:
            raise CheckFailed(f"layer {lay}: a polygon has {maxv} vertices, over the cap {cap}")
        etch_sum += got.astype(np.uint8) << bit
        del got, polys
    if not np.array_equal((n_levels - 1) - etch_sum.astype(np.int64), levels):
        raise CheckFailed("Σ 2^m·mask_m read back from the file does not reproduce the level map")
    report["levels_reproduced"] = True
    _check_marks(layers, n_masks, gds.name, cap)
    report["marks_present"] = True
    if use_klayout:
        report["klayout"] = _klayout_check(folder, man, levels, n_levels, pitch_nm)
    return report


def _check_marks(layers: dict, n_masks: int, gds_name: str, cap: int) -> None:
    """Chrome aperture, die outline, and keys, verniers and CD ladder on the chrome plate and each of the
    ``n_masks`` etch plates, every polygon within the vertex cap."""
    for key, what in (((CHROME_LAYER, 0), "chrome aperture"), ((OUTLINE_LAYER, 0), "die outline")):
        if key not in layers or len(layers[key]) < 1:
            raise CheckFailed(f"{what} (layer {key[0]}) is missing from {gds_name}")
    for plate in range(n_masks + 1):
        keys = len(layers[(KEY_LAYER, plate)]) if (KEY_LAYER, plate) in layers else 0
        vern = len(layers[(VERNIER_LAYER, plate)]) if (VERNIER_LAYER, plate) in layers else 0
        if keys < 8 or vern < 31:
            raise CheckFailed(f"plate {plate}: alignment keys ({keys}) or verniers/CD ladder ({vern}) are missing")
    for key, p in layers.items():
        if p.max_vertices > cap:
            raise CheckFailed(f"layer {key[0]}/{key[1]}: a polygon has {p.max_vertices} vertices, over the cap {cap}")


def _read(gds: Path, only: set) -> dict:
    try:
        return read_gds_layers(gds, only=only)
    except CheckFailed:
        raise
    except Exception as exc:  # noqa: BLE001 - gdstk reports a damaged file as RuntimeError/OSError/...
        raise CheckFailed(f"{gds} cannot be read as GDSII ({exc.__class__.__name__}: {exc}): the file is corrupt or "
                          f"truncated; export the set again") from None


def _klayout_check(folder: Path, man: dict, levels: np.ndarray, n_levels: int, pitch_nm: int) -> dict:
    """Second reader: KLayout's areas per etch layer, and OASIS ≡ GDS by XOR (skipped if not installed)."""
    try:
        import klayout.db as kdb
    except ImportError:
        return {"checked": False, "reason": "klayout not installed"}
    def load(name: str):
        lay = kdb.Layout()
        try:
            lay.read(str(folder / name))
        except RuntimeError as exc:
            raise CheckFailed(f"KLayout cannot read {folder / name} ({' '.join(str(exc).split())[:200]}): the file "
                              f"is corrupt or truncated; export the set again") from None
        if lay.top_cell() is None:
            raise CheckFailed(f"KLayout finds no top cell in {folder / name}: the file is empty or corrupt")
        return lay

    gds = load(man["files"]["gds"])
    top = gds.top_cell()
    out = {"checked": True, "layers": {}}
    oas = load(man["files"]["oasis"]) if man["files"].get("oasis") else None
    for bit in range(mask_count(n_levels)):
        lay = etch_layer(bit)
        li = gds.find_layer(lay, 0)
        region = kdb.Region(top.begin_shapes_rec(li)) if li is not None else kdb.Region()
        area_px = region.area() * (gds.dbu * 1000) ** 2 / pitch_nm**2
        expected = int(bit_plane(levels, bit, n_levels).sum())
        if abs(area_px - expected) > 1e-6:
            raise CheckFailed(f"KLayout: layer {lay} covers {area_px:.1f} pixels, the bit plane {expected}")
        entry = {"area_px": int(round(area_px))}
        if oas is not None:
            lo = oas.find_layer(lay, 0)
            other = kdb.Region(oas.top_cell().begin_shapes_rec(lo)) if lo is not None else kdb.Region()
            xor = region ^ other
            if not xor.is_empty():
                raise CheckFailed(f"KLayout: OASIS layer {lay} differs from GDS (XOR area {xor.area()} dbu²)")
            entry["oasis_identical"] = True
        out["layers"][str(lay)] = entry
    return out
