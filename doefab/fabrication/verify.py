"""Read a mask set back and prove it: every polygon of every layer is where the manifest and the design put it.

Checks (all in the report; any failure fails the export or ``doefab masks --verify``):
every etch depth, the level step and the level → height table re-derived from the manifest's material and
design wavelength (``manifest.depth_problems``), each layer listed once in the manifest, README.txt equal to what
the manifest says, every etch polygon inside the pixel grid and on it, zero mismatched pixels per etch layer
(gdstk reader; KLayout's too where installed), Σ 2^m·mask_m reproduces the level map, the chrome aperture, every
plate's keys, windows, verniers and CD ladder and the die outline equal to what the manifest describes within
two database units (:mod:`doefab.fabrication.layout_check`), no geometry on a layer the set does not hold or the
manifest does not list, every polygon within the vertex cap, the level map's checksum equals the manifest's. The
OASIS file, where the set has one, gets every one of these layout checks too (gdstk), and KLayout finds it equal
to the GDS file on every layer. A width/space report at the critical dimension lists features below it and
isolated single pixels.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from doefab.errors import CheckFailed, DoefabError
from doefab.fabrication.bitplanes import bit_plane, rasterize_manhattan
from doefab.fabrication.klayout_check import klayout_check
from doefab.fabrication.levels import levels_sha256
from doefab.fabrication.layers import etch_layer
from doefab.fabrication.layout_check import check_layout, expected_layout, listed_layers
from doefab.fabrication.layout_read import LayerPolygons, LayoutFile
from doefab.io import read_json
from doefab.fabrication.manifest import MASK_SET_FORMAT, depth_problems, fab_readme, manifest_levels
from doefab.fabrication.inspection import preview_names
from doefab.fabrication.process import mask_count

__all__ = ["verify_mask_set"]


def _to_pixels(polys: LayerPolygons, origin_nm: tuple[int, int], pitch_nm: int, shape: tuple[int, int], lay: int):
    """Vertices in pixels (column, row) and their polygon index; CheckFailed for a vertex outside the pixel grid
    or between its lines."""
    pts = polys.points
    idx = np.repeat(np.arange(len(polys.counts)), polys.counts)
    col = pts[:, 0] - origin_nm[0]
    row = origin_nm[1] - pts[:, 1]
    outside = (col < 0) | (row < 0) | (col > shape[1] * pitch_nm) | (row > shape[0] * pitch_nm)
    if outside.any():
        x, y = pts[np.argmax(outside)] / 1e3
        x0, y1 = origin_nm[0] / 1e3, origin_nm[1] / 1e3
        raise CheckFailed(f"layer {lay}: {len(np.unique(idx[outside]))} polygon(s) reach outside the "
                          f"{shape[0]} × {shape[1]} pixel grid (x {x0:g} … {x0 + shape[1] * pitch_nm / 1e3:g} µm, "
                          f"y {y1 - shape[0] * pitch_nm / 1e3:g} … {y1:g} µm), e.g. a vertex at ({x:g}, {y:g}) µm: "
                          f"an etch layer holds only its bit plane's pixels; export the set again from its design")
    if np.any(col % pitch_nm) or np.any(row % pitch_nm):
        raise CheckFailed(f"layer {lay}: a polygon vertex lies off the design grid (not an integer number of "
                          f"{pitch_nm} nm pixels); export the set again from its design")
    return np.stack([col // pitch_nm, row // pitch_nm], axis=1), idx


def _check_manifest(man, mpath: Path) -> None:
    """The manifest fields verification relies on, checked for type and range."""
    def need(ok: bool, key: str, what: str):
        if not ok:
            raise CheckFailed(f"{mpath}: {key} {what}")

    need(isinstance(man, dict), "(top level)", "must be a JSON object")
    need(str(man.get("format", "")).startswith("doefab mask set"), "format", f"is not '{MASK_SET_FORMAT}'")
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
    for key in ("layers", "other_layers"):
        need(isinstance(man.get(key), list) and all(isinstance(L, dict) for L in man[key]), key,
             "must be a list of layer records")
    _check_listed_once(man, mpath)


def _check_listed_once(man: dict, mpath: Path) -> None:
    """Each layer, a GDS layer number, once across ``layers`` and ``other_layers``: the fab reads one purpose per
    layer."""
    seen: dict = {}
    for key in ("layers", "other_layers"):
        for i, L in enumerate(man[key]):
            lay = L.get("layer")
            if isinstance(lay, bool) or not isinstance(lay, int) or not 0 <= lay <= 65535:
                raise CheckFailed(f"{mpath}: {key}[{i}].layer = {lay!r} is not a GDS layer number (0–65535, e.g. "
                                  f"100 for the die outline); export the set again")
            if lay in seen:
                raise CheckFailed(f"{mpath}: {key}[{i}] lists layer {lay!r} ({L.get('purpose')!r}) again, after "
                                  f"{seen[lay]}: each layer must be listed once; delete the repeated entry or export "
                                  f"the set again")
            seen[lay] = f"{key}[{i}]"


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
        man = read_json(mpath)
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
    levels = _level_map(folder, man, levels, n_levels)
    expected = expected_layout(man, n_masks)  # chrome, marks and outline as the manifest describes them
    report: dict = {"gds": man["files"]["gds"], "ok": True}
    verified: dict = {}  # etch layer → (SHA-256 of its vertices, file) once it has passed
    report.update(_check_layout_file(LayoutFile(folder / man["files"]["gds"]), man, levels, n_levels, expected,
                                     verified))
    report["marks_present"] = report["levels_reproduced"] = True
    if man["files"].get("oasis"):  # the same checks: the fab may write either file
        oasis = LayoutFile(folder / man["files"]["oasis"], oasis=True)
        report["oasis"] = {"file": oasis.path.name,
                           **_check_layout_file(oasis, man, levels, n_levels, expected, verified)}
    if use_klayout:
        report["klayout"] = klayout_check(folder, man, levels, n_levels, expected)
    return report


def _check_layout_file(layout: LayoutFile, man: dict, levels: np.ndarray, n_levels: int, expected: dict,
                       verified: dict) -> dict:
    """Every layer of one layout file (GDSII or OASIS) read with gdstk: no stray or unlisted layer, the chrome,
    marks and outline as the manifest draws them (``expected``), the vertex cap, each etch layer equal to its bit
    plane of ``levels`` (``verified``: see :func:`_check_etch_layers`); the report (``marks``, ``layers``), else
    CheckFailed naming the file and the layer."""
    etch_keys = {(etch_layer(b), 0) for b in range(mask_count(n_levels))}
    try:
        others = layout.read(layout.layers() - etch_keys)  # chrome, marks, outline and anything stray: small
        marks = check_layout({k: p.polygons() for k, p in others.items()}, expected, set(expected) | etch_keys,
                             listed_layers(man))
        _check_cap(others, int(man["vertex_cap"]))
        return {"marks": marks, "layers": _check_etch_layers(layout, man, levels, n_levels, verified)}
    except CheckFailed as exc:
        msg = str(exc)
        raise CheckFailed(msg if msg.startswith(str(layout.path)) else f"{layout.path}: {msg}") from None
    finally:
        layout.close()


def _level_map(folder: Path, man: dict, levels, n_levels: int) -> np.ndarray:
    """The set's level map (given, or its design/levels.npy) checked against the manifest, as drawn in the layout
    (mirrored in x when the pattern faces the lens)."""
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
    levels = np.asarray(levels, np.uint8)
    return np.ascontiguousarray(levels[:, ::-1]) if man.get("mirrored_x", False) else levels


def _check_cap(layers: dict, cap: int) -> None:
    for key, p in layers.items():
        if p.max_vertices > cap:
            raise CheckFailed(f"layer {key[0]}/{key[1]}: a polygon has {p.max_vertices} vertices, over the cap {cap} "
                              f"(manifest.json vertex_cap); export the set again")


def _etched(polys: LayerPolygons, man: dict, shape: tuple[int, int], lay: int) -> np.ndarray:
    """The pixels etch layer ``lay`` covers, rasterised from its polygons; CheckFailed for a polygon off the
    pixel grid, overlapping or inverted."""
    pitch_nm = int(round(man["pitch_m"] * 1e9))
    origin_nm = (int(round(man["origin_m"][0] * 1e9)), int(round(man["origin_m"][1] * 1e9)))
    if not len(polys):
        return np.zeros(shape, bool)
    pix, idx = _to_pixels(polys, origin_nm, pitch_nm, shape, lay)
    try:
        wind = rasterize_manhattan(pix, idx, shape)
    except DoefabError as exc:
        raise CheckFailed(f"layer {lay}: {exc}; export the set again from its design") from None
    if np.any(wind < 0) or np.any(wind > 1):
        raise CheckFailed(f"layer {lay}: overlapping or inverted polygons (winding number {wind.min()}..{wind.max()}); "
                          f"export the set again from its design")
    return wind.astype(bool)


def _digest(polys: LayerPolygons) -> str:
    """SHA-256 of a layer's polygons (vertex counts and integer vertices, in order)."""
    h = hashlib.sha256(polys.counts.tobytes())
    h.update(polys.points.tobytes())
    return h.hexdigest()


def _check_etch_layers(layout: LayoutFile, man: dict, levels: np.ndarray, n_levels: int, verified: dict) -> dict:
    """Each etch layer rasterised from the file equals its bit plane of ``levels`` (as drawn), and Σ 2^m·mask_m
    reproduces the level map; the per-layer report. ``verified``: layer → (SHA-256 of its vertices, file) of the
    etch layers another file of the set passed with: a layer identical to one of them (the OASIS written from the
    GDS) has passed already and is not rasterised again; this file's layers are added to it."""
    out = {}
    etch_sum = np.zeros(levels.shape, np.uint8)
    for bit in range(mask_count(n_levels)):
        lay = etch_layer(bit)
        # one etch layer at a time keeps the peak memory to one layer's polygons
        polys = layout.read({(lay, 0)}).get((lay, 0), LayerPolygons.empty())
        digest, plane, seen = _digest(polys), bit_plane(levels, bit, n_levels), verified.get(lay)
        same_as = seen[1] if seen and seen[0] == digest else None  # the file whose identical layer passed
        got = plane if same_as else _etched(polys, man, levels.shape, lay)
        mism = 0 if same_as else int(np.count_nonzero(got != plane))
        out[str(lay)] = {"polygons": len(polys), "vertices": int(polys.counts.sum()),
                         "max_vertices": polys.max_vertices, "mismatched_pixels_gdstk": mism}
        if same_as:
            out[str(lay)]["identical_to"] = same_as
        if mism:
            raise CheckFailed(f"layer {lay}: {mism} pixels differ from the design's bit plane {bit}; export the set "
                              f"again from its design")
        _check_cap({(lay, 0): polys}, int(man["vertex_cap"]))
        verified.setdefault(lay, (digest, layout.path.name))
        etch_sum += got.astype(np.uint8) << bit
        del got, polys
    if not np.array_equal((n_levels - 1) - etch_sum.astype(np.int64), levels):
        raise CheckFailed("Σ 2^m·mask_m read back from the file does not reproduce the level map; export the set "
                          "again from its design")
    return out
