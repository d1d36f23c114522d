"""Export an L-level design as M = log2 L binary photomask layers with chrome, marks, manifest and previews.

``export_masks`` writes into a staging folder, verifies everything by reading the files back, and only
then moves the folder into place: no half-written mask set survives a failure.
"""

from __future__ import annotations

import io
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from doefab.diekey import (DEFAULT_CHAMFER_MM, DEFAULT_THICKNESS_MM, LEAST_CLEARANCE_MM, SECOND_CHAMFER,
                           chamfer_problem, least_key_chamfer_mm)
from doefab.errors import DoefabError
from doefab.fabrication.bitplanes import bit_plane, plane_rectangles, validate_levels
from doefab.fabrication.gdsii import GDSWriter
from doefab.fabrication.layers import (CHROME_LAYER, KEY_LAYER, LAYER_PURPOSES,
                                       VERNIER_LAYER, etch_bit, etch_layer)
from doefab.fabrication.levels import levels_sha256
from doefab.fabrication.manifest import MASK_SET_FORMAT, depth_fields, fab_readme
from doefab.fabrication.marks import (CLEAR_MARGIN_NM, MarkSpec, clear_boxes, key_site, mark_layout, mark_polygons,
                                     nm_to_m, split_slits, vernier_record)
from doefab.fabrication.process import DEFAULT_LEVELS, check_levels, mask_count
from doefab.fabrication.inspection import check_marks_clear, layer_widths, write_previews
from doefab.fabrication.verify import verify_mask_set
from doefab.io import OutputDir, atomic_write_json, atomic_write_text, mark_folder, plain_name, read_json, staging_dir
from doefab.optics.camera import Camera, require_camera

__all__ = ["MaskOptions", "LevelMap", "export_masks", "layout_levels"]


@dataclass
class MaskOptions:
    """Mask-set options (SI units).

    Attributes:
        name: base name of the GDS/OASIS files.  oasis: also write OASIS (identical geometry).
        die_m: die (plate pattern) size, square, metres.  die_chamfer_m: the dicing outline's key, the larger of
            the two chamfers on the coded half's corners (``doefab.diekey``; the holder's ``die_chamfer_mm``),
            metres; 0: a square die; None: the holder's default, 2 mm, or a quarter of a die of 4 mm or less.
        cd_m: critical dimension (default: the pixel pitch).
        substrate_thickness_m: the substrate's thickness, metres (the holder's ``die_thickness_mm``; 1 mm).
        vertex_cap: maximum vertices per polygon (GDSII allows 8190; 4000 is conservative).
        align_chain: ``"chrome"`` (every etch mask aligns to the chrome keys; errors don't accumulate) or
            ``"sequential"`` (mask k aligns to the plate written before it).
        etch_order: etch layers in process order (default deepest first: 4, 3, 2, 1 for 16 levels; layer 6 is
            the fifth mask's, 32 levels).
        resist: ``"positive"`` or ``"negative"``; sets the plate polarity stated in the manifest.
        depth_tolerance: relative etch-depth tolerance stated to the fab.
        use_klayout: verify with KLayout too (where installed).
        pattern_faces: which way the etched face points once mounted: ``"lens"`` (the holder's default,
            closest to the aperture) or ``"scene"``. The design is defined looking from the scene into the
            camera while a layout is drawn as seen from its patterned face, so with the pattern toward the
            lens the layout is the design mirrored in x (stated in the manifest).
    """

    name: str = "doe"
    oasis: bool = False
    die_m: float = 12e-3
    die_chamfer_m: float | None = None
    cd_m: float | None = None
    substrate_thickness_m: float = DEFAULT_THICKNESS_MM * 1e-3
    vertex_cap: int = 4000
    align_chain: str = "chrome"
    etch_order: tuple | None = None
    resist: str = "positive"
    depth_tolerance: float = 0.03
    use_klayout: bool = True
    pattern_faces: str = "lens"
    extra: dict = field(default_factory=dict)


def _chamfer_m(opts: MaskOptions) -> float:
    """The die key's larger chamfer (m): as given, else the holder's default (a quarter of a die of 4 mm or less,
    which that would cut in half)."""
    if opts.die_chamfer_m is not None:
        return opts.die_chamfer_m
    return DEFAULT_CHAMFER_MM * 1e-3 if DEFAULT_CHAMFER_MM * 1e-3 < opts.die_m / 2 else opts.die_m / 4


def _chamfer_nm(opts: MaskOptions) -> int:
    """The die key's larger chamfer in nm, even (both legs whole nanometres)."""
    return 2 * int(round(_chamfer_m(opts) * 0.5e9))


def _nm(value_m: float, what: str) -> int:
    v = value_m * 1e9
    if abs(v - round(v)) > 1e-6 * max(1.0, abs(v)):
        raise DoefabError(f"{what} = {value_m:g} m is not an integer number of nanometres (the 1 nm database unit): "
                          f"the pixel edges would fall off the layout grid; use a pitch like 5.4e-6")
    return int(round(v))


@dataclass(frozen=True)
class LevelMap:
    """A level map to make masks of, with what ``export_masks`` reads from a design: a ``doefab.Design`` carries
    the same three fields, so either may be exported.

    Attributes:
        levels: (N, N) integer levels 0..L−1 (row 0 = top, column 0 = left, x < 0 the coded half).
        camera: gives the DOE pitch and grid, the design wavelength and the material.
        n_levels: L, the levels the fab makes (2, 4, 8, 16 or 32: log2 L etch layers).

    Example:
        >>> import numpy as np
        >>> from doefab.optics.camera import Camera
        >>> cam = Camera.preset("hdr")
        >>> LevelMap(np.zeros((cam.doe_pixels,) * 2, np.uint8), cam, n_levels=4).n_levels
        4
    """

    levels: np.ndarray
    camera: Camera
    n_levels: int = DEFAULT_LEVELS

    def __post_init__(self) -> None:
        require_camera(self.camera, "LevelMap.camera")


def export_masks(design, out_dir: str | Path, options: MaskOptions | None = None, *,
                 design_dir: str | Path | None = None, force: bool = False, progress: bool = True) -> dict:
    """Write and verify a mask set for a design's level map on its camera's DOE grid.

    Args:
        design: a ``doefab.Design`` or a ``LevelMap``: its ``levels`` (N, N), ``camera`` and ``n_levels`` (L).
        out_dir: the mask-set folder (must not exist unless ``force``).
        options: the mask-set options (``MaskOptions``; default ``MaskOptions()``).
        design_dir: the design folder it came from; its design.json and levels.npy are copied into
            ``out_dir/design`` so the set can be re-verified and traced (its recorded ``n_levels`` must be
            the design's).
    Returns:
        The verification report (also in ``out_dir/report.json``).
    """
    levels, camera, n_levels = _parts_of(design, design_dir)
    opts = options or MaskOptions()
    t0 = time.perf_counter()
    lv = validate_levels(levels, n_levels)
    n = camera.doe_pixels
    if lv.shape != (n, n):
        raise DoefabError(f"level map shape {lv.shape} does not match the camera grid ({n}, {n}) at pitch "
                          f"{camera.doe_pitch:g} m: wrong design or camera")
    order = _check_options(opts, n_levels, camera.doe_pitch)
    pitch_nm = _nm(camera.doe_pitch, "DOE pitch")
    die_nm = _nm(opts.die_m, "die size")
    cd_nm = _nm(opts.cd_m if opts.cd_m is not None else camera.doe_pitch, "critical dimension")
    extent_nm = n * pitch_nm
    if die_nm < extent_nm + 2 * 1_000_000:
        raise DoefabError(f"die {opts.die_m * 1e3:g} mm leaves no 1 mm margin around the {extent_nm / 1e6:g} mm "
                          f"pattern for marks: the die must be at least {extent_nm / 1e6 + 2:g} mm (enlarge die_m)")
    chamfer = chamfer_problem(opts.die_m * 1e3, _chamfer_m(opts) * 1e3)
    if chamfer:
        raise DoefabError(f"die_chamfer_m = {_chamfer_m(opts):g} m: {chamfer} (the holder's die_chamfer_mm)")
    out = OutputDir(out_dir, "masks", replace=force).path
    origin_nm = (-(extent_nm // 2), extent_nm // 2)  # top-left corner of pixel (0, 0)
    layout = layout_levels(lv, opts.pattern_faces)
    widths = layer_widths(layout, n_levels, cd_nm, pitch_nm, origin_nm)
    writer = GDSWriter(cell_name=opts.name.upper()[:32] or "DOE")
    layer_stats = _write_etch_layers(writer, layout, n_levels, pitch_nm, origin_nm)
    spec = _mark_spec(camera, opts, die_nm, cd_nm)
    align_to = _alignment(order, opts.align_chain)
    bare = clear_boxes(mark_polygons(spec, align_to), spec.clear_margin_nm) + split_slits(spec)  # chrome-free glass
    check_marks_clear(layout, n_levels, bare, pitch_nm, origin_nm)
    for points, layer, datatype in mark_layout(spec, align_to, opts.vertex_cap, CHROME_LAYER):
        writer.add_polygon(points, layer, datatype)
    with staging_dir(out) as stage:
        gds_name = f"{opts.name}.gds"
        writer.write(stage / gds_name)
        del writer
        files = {"gds": gds_name}
        if opts.oasis:
            import gdstk

            lib = gdstk.read_gds(str(stage / gds_name))
            lib.write_oas(str(stage / f"{opts.name}.oas"))
            files["oasis"] = f"{opts.name}.oas"
        design_sub = stage / "design"
        design_sub.mkdir()
        buf = io.BytesIO()
        np.save(buf, lv)
        (design_sub / "levels.npy").write_bytes(buf.getvalue())
        if design_dir is not None and (Path(design_dir) / "design.json").is_file():
            shutil.copyfile(Path(design_dir) / "design.json", design_sub / "design.json")
        mark_folder(stage, "masks")
        manifest = _manifest(camera, opts, lv, n_levels, pitch_nm, origin_nm, files, align_to, order, cd_nm, die_nm)
        atomic_write_json(stage / "manifest.json", manifest)
        report = verify_mask_set(stage, lv, use_klayout=opts.use_klayout, complete=False)  # mirrors per the manifest
        report["width_space"] = widths
        for lay, nrect in layer_stats.items():
            report["layers"][str(lay)]["rectangles_written"] = nrect
            report["layers"][str(lay)]["gds_bytes"] = 64 * nrect  # one BOUNDARY record set per rectangle
        report["file_bytes"] = {k: (stage / v).stat().st_size for k, v in files.items()}
        report["export_seconds"] = round(time.perf_counter() - t0, 3)
        write_previews(stage, layout, n_levels, camera.doe_pitch, mirrored=opts.pattern_faces == "lens")
        atomic_write_text(stage / "README.txt", fab_readme(manifest))
        atomic_write_json(stage / "report.json", report)
    return report


def _write_etch_layers(writer: GDSWriter, layout: np.ndarray, n_levels: int, pitch_nm: int,
                       origin_nm: tuple[int, int]) -> dict:
    """Each etch layer's rectangles added to ``writer`` (nm, y up, ``origin_nm`` the top-left corner of pixel
    (0, 0)), one bit plane at a time (the 8640² case stays within a few GB): {layer: rectangles written}."""
    stats = {}
    for bit in range(mask_count(n_levels)):
        r = plane_rectangles(bit_plane(layout, bit, n_levels))
        x0 = origin_nm[0] + r[:, 0] * pitch_nm
        x1 = origin_nm[0] + r[:, 2] * pitch_nm
        y1 = origin_nm[1] - r[:, 1] * pitch_nm
        y0 = origin_nm[1] - r[:, 3] * pitch_nm
        writer.add_rectangles(np.stack([x0, y0, x1, y1], axis=1), etch_layer(bit))
        stats[etch_layer(bit)] = len(r)
    return stats


def _alignment(order: list[int], chain: str) -> dict:
    """{mask number (etch bit + 1): the plate it aligns to (0: the chrome)} for the etch layers in process order:
    every mask to the chrome (``chain`` "chrome"), or each to the one etched before it."""
    out = {}
    for k, lay in enumerate(order):
        out[etch_bit(lay) + 1] = 0 if (chain == "chrome" or k == 0) else etch_bit(order[k - 1]) + 1
    return out


def _check_options(opts: MaskOptions, n_levels: int, pitch: float) -> list[int]:
    """Every mask option in its range (one error naming it); returns the etch layers in process order."""
    etch_layers = [etch_layer(b) for b in range(mask_count(n_levels))]
    order = list(opts.etch_order) if opts.etch_order is not None else etch_layers[::-1]
    if opts.align_chain not in ("chrome", "sequential"):
        raise DoefabError(f"align_chain must be 'chrome' or 'sequential', got {opts.align_chain!r}")
    if sorted(order) != etch_layers:
        raise DoefabError(f"etch_order must name each of the {len(etch_layers)} etch layers {etch_layers} once (a "
                          f"{n_levels}-level set), got {opts.etch_order!r}")
    if opts.pattern_faces not in ("lens", "scene"):
        raise DoefabError(f"pattern_faces must be 'lens' or 'scene', got {opts.pattern_faces!r}")
    if opts.resist not in ("positive", "negative"):
        raise DoefabError(f"resist must be 'positive' or 'negative', got {opts.resist!r}")
    if not isinstance(opts.vertex_cap, int) or not 5 <= opts.vertex_cap <= 8190:
        raise DoefabError(f"vertex_cap must be an integer in 5..8190 (GDSII allows 8190), got {opts.vertex_cap!r}")
    plain_name(opts.name, "mask-set name")
    for what, v, lo, hi in (("die size die_m", opts.die_m, 1e-3, 0.3),
                            ("substrate thickness substrate_thickness_m", opts.substrate_thickness_m, 1e-4, 1e-2),
                            ("critical dimension cd_m", pitch if opts.cd_m is None else opts.cd_m, 1e-7, 1e-3)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
            raise DoefabError(f"{what} = {v!r} m is outside {lo:g}–{hi:g} m")
    c = _chamfer_m(opts)
    if isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c) or c < 0:
        raise DoefabError(f"die_chamfer_m = {c!r} m must be a length ≥ 0: the holder's die_chamfer_mm, "
                          f"{DEFAULT_CHAMFER_MM:g} mm by default")
    if opts.die_chamfer_m is not None and 0 < c * 1e3 <= (least := least_key_chamfer_mm(LEAST_CLEARANCE_MM)):
        raise DoefabError(f"a die key chamfer of {c * 1e3:g} mm (die_chamfer_m) keys the die in no holder's pocket "
                          f"(even at the tightest {LEAST_CLEARANCE_MM:g} mm clearance a chamfer must exceed "
                          f"{least:.2f} mm): give the holder's die_chamfer_mm, {DEFAULT_CHAMFER_MM:g} mm by "
                          f"default, or 0 for an unkeyed square die")
    if not math.isfinite(opts.depth_tolerance) or not 0 < opts.depth_tolerance < 0.5:
        raise DoefabError(f"depth_tolerance {opts.depth_tolerance!r} must be a fraction in (0, 0.5)")
    return order


def _parts_of(design, design_dir) -> tuple:
    """(levels, camera, n_levels) of the design to export (its level count checked against ``design_dir``)."""
    try:
        levels, camera, n_levels = design.levels, design.camera, design.n_levels
    except AttributeError:
        raise DoefabError(f"export_masks takes a design (a doefab.Design, or LevelMap(levels, camera, n_levels) "
                          f"for a level map of your own), got {type(design).__name__}") from None
    return levels, camera, _levels_of(n_levels, design_dir)


def _levels_of(n_levels, design_dir) -> int:
    """L of the export: the design's ``n_levels``, checked against the design folder's design.json (when given)."""
    n_levels = check_levels(n_levels, "n_levels")
    meta = Path(design_dir) / "design.json" if design_dir is not None else None
    if meta is None or not meta.is_file():
        return n_levels
    try:
        recorded = read_json(meta).get("n_levels", DEFAULT_LEVELS)
    except (OSError, ValueError, AttributeError):
        raise DoefabError(f"{meta} is not a readable design record: load the design with doefab.Design.load "
                          f"to see why") from None
    recorded = check_levels(recorded, f"{meta}: n_levels")
    if recorded != n_levels:
        raise DoefabError(f"the design has {n_levels} levels but the one in {design_dir} has {recorded} levels: "
                          f"export the design that folder holds (doefab.Design.load)")
    return n_levels


def _mark_spec(camera, opts: MaskOptions, die_nm: int, cd_nm: int) -> MarkSpec:
    """The marks' geometry for ``opts``: the die, its key chamfer and side, the CD; windows for positive resist."""
    return MarkSpec(die_nm=die_nm, aperture_radius_nm=_nm(camera.aperture_diameter / 2, "aperture radius"),
                    cd_nm=cd_nm, chamfer_nm=_chamfer_nm(opts), coded_sign=1 if opts.pattern_faces == "lens" else -1,
                    windows=opts.resist == "positive")


def layout_levels(levels: np.ndarray, pattern_faces: str) -> np.ndarray:
    """The level map as drawn in the layout (seen from the patterned face): mirrored in x if it faces the lens."""
    return np.ascontiguousarray(levels[:, ::-1]) if pattern_faces == "lens" else levels


ORIGIN_MEANS = ("layout position of the top-left corner of the drawn pixel grid, x right, y up: of layout pixel "
                "[0, 0], which holds level-map (design) pixel ")


def _manifest(camera, opts, lv, n_levels, pitch_nm, origin_nm, files, align_to, order, cd_nm, die_nm) -> dict:
    depths = depth_fields(camera.material, camera.design_wavelength, n_levels)
    positive = opts.resist == "positive"
    n_masks = mask_count(n_levels)
    layers = []
    for bit in range(n_masks):
        lay = etch_layer(bit)
        depth_nm = depths["etch_depth_nm"][bit]
        plate = bit + 1
        layers.append({
            "layer": lay, "datatype": 0, "purpose": "etch", "bit": bit, "plate": plate,
            "etch_depth_nm": depth_nm,
            "etch_depth_tolerance_nm": round(max(opts.depth_tolerance * depth_nm, 2.0), 3),
            "critical_dimension_nm": cd_nm,
            "polygons_mean": f"pixels this mask etches (material removed): level = {n_levels - 1} − Σ 2^bit·etched",
            "resist_tone": opts.resist,
            "mask_polarity": ("dark field: the plate is clear (chrome removed) inside the polygons"
                              if positive else "clear field: the plate carries chrome inside the polygons"),
            "process_step": order.index(lay) + 2,
            "aligns_to_plate": align_to[plate],
            "marks": {"keys": [KEY_LAYER, plate], "verniers_cd_ladder": [VERNIER_LAYER, plate]},
        })
    layers.insert(0, {
        "layer": CHROME_LAYER, "datatype": 0, "purpose": "chrome aperture", "plate": 0, "process_step": 1,
        "polygons_mean": "chrome remains on the DOE (opaque baffle outside the clear aperture)",
        "resist_tone": opts.resist,
        "mask_polarity": ("clear field: the plate carries chrome inside the polygons" if positive else
                          "dark field: the plate is clear inside the polygons"),
        "critical_dimension_nm": cd_nm, "aligns_to_plate": None,
        "marks": {"keys": [KEY_LAYER, 0], "verniers_cd_ladder": [VERNIER_LAYER, 0]},
    })
    n = lv.shape[0]
    return {
        "format": MASK_SET_FORMAT,
        "files": files,
        "database_unit_m": 1e-9, "user_unit_m": 1e-6,
        "layers": layers,
        "other_layers": [{"layer": k, "purpose": v} for k, v in LAYER_PURPOSES.items() if k != CHROME_LAYER],
        "plates": {str(p): [f"{CHROME_LAYER if p == 0 else etch_layer(p - 1)}/0", f"{KEY_LAYER}/{p}",
                            f"{VERNIER_LAYER}/{p}"] for p in range(n_masks + 1)},
        "process_order": [CHROME_LAYER] + list(order),
        "alignment_chain": {str(k): v for k, v in align_to.items()},
        "alignment_scheme": opts.align_chain,
        "key_sites_m": {str(p): [[nm_to_m(x), nm_to_m(y)] for x, y in key_site(MarkSpec(die_nm, 0, cd_nm), p)]
                        for p in range(n_masks + 1)},
        "pitch_m": nm_to_m(pitch_nm),
        "origin_m": [nm_to_m(origin_nm[0]), nm_to_m(origin_nm[1])],
        "origin_means": ORIGIN_MEANS + ("[0, N−1] (mirrored_x)" if opts.pattern_faces == "lens" else "[0, 0]"),
        "shape": [n, n], "row0": "top",
        "layout_view": "drawn as seen from the patterned (etched) face, x right, y up",
        "pattern_faces": opts.pattern_faces,
        "mirrored_x": opts.pattern_faces == "lens",
        "mirror_means": ("the design is defined looking from the scene into the camera; with the patterned face "
                         "toward the lens the layout column j holds design column N−1−j (coded half x > 0 in "
                         "the layout)") if opts.pattern_faces == "lens" else "layout column j = design column j",
        "die_m": nm_to_m(die_nm),
        "substrate_thickness_m": round(opts.substrate_thickness_m, 12),
        "die_chamfer_m": nm_to_m(_chamfer_nm(opts)),
        "verniers": vernier_record(die_nm, cd_nm, align_to),
        "mark_clear_margin_m": nm_to_m(CLEAR_MARGIN_NM),
        "mark_clear_margin_means": "the chrome plate leaves the glass clear this far beyond every mark's bounding box",
        "die_outline_means": (f"layer 100, the dicing outline: the two corners of the coded half (x "
                              f"{'>' if opts.pattern_faces == 'lens' else '<'} 0 in the layout) chamfered, legs "
                              f"die_chamfer_m at +y and {SECOND_CHAMFER:g} × that at −y; they key the die in the "
                              "holder's pocket (not turned, not flipped), and the alignment keys they cut off are "
                              "needed only until the last etch"),
        "clear_aperture_diameter_m": camera.aperture_diameter,
        "coded_half": ("the level map's left columns (x < 0 in the design, looking from the scene); in the layout "
                       f"x {'>' if opts.pattern_faces == 'lens' else '<'} 0"),
        "design_wavelength_m": camera.design_wavelength,
        "material": camera.material.to_dict(),
        "refractive_index_at_design_wavelength": depths["refractive_index_at_design_wavelength"],
        "n_levels": n_levels, "n_masks": n_masks,
        "level_step_nm": depths["level_step_nm"],
        "level_to_height_nm": depths["level_to_height_nm"],
        "height_means": f"material above the deepest etch; level {n_levels - 1} = unetched surface",
        "levels_sha256": levels_sha256(lv),
        "levels_sha256_means": "SHA-256 of the design's level map (design.json), before any mirroring",
        "vertex_cap": opts.vertex_cap,
    }
