"""What a mask set tells the fab about depths, derived in one place and re-derived on verification.

The fab reads the etch depths from ``manifest.json`` (and its human copy ``README.txt``): every depth, the
level step and the level → height table follow from the substrate and the design wavelength alone
and the number of levels L (d = λ / (n(λ) − 1) / L, mask m of M = log2 L etches 2^m·d, level k stands k·d above
the deepest etch). ``depth_fields`` writes them; ``depth_problems`` recomputes them from the manifest's own
material (looked up by name among the built-in substrates), design wavelength and ``n_levels`` (a set written
before it was recorded has 16 levels) and names every field that disagrees.
"""

from __future__ import annotations

import math
from pathlib import Path

from doefab.diekey import SECOND_CHAMFER
from doefab.errors import DoefabError
from doefab.fabrication.levels import material_level_step
from doefab.fabrication.process import DEFAULT_LEVELS, check_levels, mask_count
from doefab.io import read_json
from doefab.optics.materials import Material

__all__ = ["depth_fields", "depth_problems", "fab_readme", "manifest_levels", "DEPTH_TOLERANCE_NM", "MASK_SET_FORMAT",
           "drawn_before_3"]

_FORMATS = {"gds": "GDSII", "oasis": "OASIS"}  # the manifest's file keys, as a fab names the formats
# the manifest's format: 2 adds the keyed die outline and the marks' clear fields, and the README words the files'
# formats and the layout's view as a fab reads them; a set of format 1 keeps its README's words (it still verifies);
# 3 gives each etch plate its own x and y verniers (``verniers``), marks at least the CD wide, one-polygon key
# crosses and, for negative resist, no windows (a set of format 1 or 2 verifies as it was drawn: ``drawn_before_3``)
MASK_SET_FORMAT = "doefab mask set 3"


def drawn_before_3(man: dict) -> bool:
    """Whether the manifest ``man`` is of a set of format 1 or 2, whose marks are drawn and described as they were
    then (``marks.MarkSpec.legacy``)."""
    return man.get("format") in ("doefab mask set 1", "doefab mask set 2")

# the manifest rounds depths to 0.001 nm; a field further than this from its re-derived value was edited
DEPTH_TOLERANCE_NM = 0.002


def depth_fields(material: Material, design_wavelength: float, n_levels: int = DEFAULT_LEVELS) -> dict:
    """The manifest's depth fields (nm) for ``material`` at ``design_wavelength`` (m) and ``n_levels`` levels:
    index, level step, level → height table, and the etch depth of each mask (``etch_depth_nm[bit]``)."""
    d_nm = material_level_step(material, design_wavelength, n_levels) * 1e9
    return {"refractive_index_at_design_wavelength": float(material.index(design_wavelength)),
            "level_step_nm": round(d_nm, 4),
            "level_to_height_nm": [round(k * d_nm, 3) for k in range(n_levels)],
            "etch_depth_nm": [round((1 << bit) * d_nm, 3) for bit in range(mask_count(n_levels))]}


def manifest_levels(man: dict) -> int:
    """The manifest's number of levels (``n_levels``; 16 for sets written before it was recorded); a DoefabError
    when it is not one a mask process makes."""
    return check_levels(man.get("n_levels", DEFAULT_LEVELS), "n_levels")


def _off(got, want: float, tol: float) -> bool:
    return isinstance(got, bool) or not isinstance(got, (int, float)) or not abs(got - want) <= tol


def _material(man: dict) -> tuple[Material | None, list[str]]:
    rec = man.get("material")
    name = rec.get("name") if isinstance(rec, dict) else None
    if not isinstance(name, str):
        return None, [f"material = {rec!r} does not name a substrate"]
    try:  # a material of the user's own with its coefficients; a built-in name with edited ones is refused
        material = Material.from_dict(rec, where="material")
    except DoefabError as exc:
        return None, [f"material: {exc}"]
    return material, []


def depth_problems(man: dict, design_json: Path | None = None) -> list[str]:
    """Every depth field of the manifest ``man`` that disagrees with its material and design wavelength (and,
    given the set's ``design/design.json``, every disagreement with the design's camera); [] when consistent."""
    material, problems = _material(man)
    try:
        n_levels = manifest_levels(man)
    except DoefabError as exc:
        return problems + [str(exc)]
    if man.get("n_masks", mask_count(n_levels)) != mask_count(n_levels):
        problems.append(f"n_masks = {man['n_masks']!r} (expected {mask_count(n_levels)} for {n_levels} levels)")
    lam = man.get("design_wavelength_m")
    if isinstance(lam, bool) or not isinstance(lam, (int, float)) or not 200e-9 <= lam <= 2e-6:
        problems.append(f"design_wavelength_m = {lam!r} is not a wavelength in metres within 200 nm – 2 µm")
        lam = None
    if design_json is not None and design_json.is_file():
        problems += _against_design(man, design_json)
    if material is None or lam is None:
        return problems
    want = depth_fields(material, lam, n_levels)
    if _off(man.get("refractive_index_at_design_wavelength"), want["refractive_index_at_design_wavelength"], 1e-9):
        problems.append(f"refractive_index_at_design_wavelength = {man.get('refractive_index_at_design_wavelength')!r}"
                        f" (expected {want['refractive_index_at_design_wavelength']:.10g})")
    if _off(man.get("level_step_nm"), want["level_step_nm"], DEPTH_TOLERANCE_NM):
        problems.append(f"level_step_nm = {man.get('level_step_nm')!r} (expected {want['level_step_nm']})")
    table = man.get("level_to_height_nm")
    if not isinstance(table, list) or len(table) != n_levels:
        problems.append(f"level_to_height_nm must list {n_levels} heights (n_levels), got {table!r}")
    else:
        problems += [f"level_to_height_nm[{k}] = {h!r} (expected {w})" for k, (h, w) in
                     enumerate(zip(table, want["level_to_height_nm"])) if _off(h, w, DEPTH_TOLERANCE_NM)]
    return problems + _etch_problems(man.get("layers"), want["etch_depth_nm"])


def _etch_problems(layers, depths_nm: list[float]) -> list[str]:
    if not isinstance(layers, list) or not all(isinstance(L, dict) for L in layers):
        return ["layers must be a list of layer records"]
    etch = [(i, L) for i, L in enumerate(layers) if L.get("purpose") == "etch"]
    bits = sorted(L.get("bit") for _, L in etch if isinstance(L.get("bit"), int))
    if bits != list(range(len(depths_nm))):
        return [f"layers: the etch layers of {1 << len(depths_nm)} levels must carry bits 0..{len(depths_nm) - 1} "
                f"once each, got {bits}"]
    problems = []
    for i, L in etch:
        want, got, tol = depths_nm[L["bit"]], L.get("etch_depth_nm"), L.get("etch_depth_tolerance_nm")
        if _off(got, want, DEPTH_TOLERANCE_NM):
            problems.append(f"layers[{i}].etch_depth_nm = {got!r} (expected {want} for bit {L['bit']})")
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol <= max(0.5 * want, 2.0):
            problems.append(f"layers[{i}].etch_depth_tolerance_nm = {tol!r} is not a tolerance of a {want} nm "
                            f"etch (0 < tolerance ≤ half the depth)")
    return problems


def _against_design(man: dict, design_json: Path) -> list[str]:
    try:
        meta = read_json(design_json)
        cam = meta["camera"]
        lam, name = float(cam["design_wavelength_m"]), cam["material"]["name"]
        levels = meta.get("n_levels", DEFAULT_LEVELS)
    except (OSError, ValueError, KeyError, TypeError):
        return [f"{design_json} is not a readable design record (camera.design_wavelength_m, camera.material)"]
    problems = []
    if man.get("n_levels", DEFAULT_LEVELS) != levels:
        problems.append(f"n_levels = {man.get('n_levels', DEFAULT_LEVELS)!r} differs from the design's {levels!r} "
                        f"({design_json})")
    if isinstance(man.get("design_wavelength_m"), (int, float)) and not math.isclose(
            man["design_wavelength_m"], lam, rel_tol=1e-9):
        problems.append(f"design_wavelength_m = {man['design_wavelength_m']!r} differs from the design's {lam!r} "
                        f"({design_json})")
    if isinstance(man.get("material"), dict) and man["material"].get("name") != name:
        problems.append(f"material {man['material'].get('name')!r} differs from the design's {name!r}")
    return problems


def _clear_fields(man: dict) -> str:
    """The README's words on the clear fields round the marks, from the manifest (none in an older set)."""
    m = man.get("mark_clear_margin_m") or 0.0
    if not m:
        return ""
    return (f" The chrome plate leaves the glass clear {m * 1e6:g} µm beyond every mark of every plate: its keys, "
            "verniers and CD ladder are chrome inside those clear fields, and the etch plates' marks land on bare "
            "silica.")


def _thickness(man: dict) -> str:
    """The README's words on the substrate's thickness (none in a set written before it was stated)."""
    t = man.get("substrate_thickness_m")
    return f", {t * 1e3:g} mm thick" if t else ""


def _verniers(man: dict) -> str:
    """The README's words on reading the verniers, from the manifest (none in a set of format 1 or 2)."""
    v = man.get("verniers")
    if not v:
        return ""
    return (f" Verniers: {v['reads']}; {v['bars']} bars {v['bar_width_nm'] / 1e3:g} µm wide, the reference at "
            f"{v['reference_pitch_nm'] / 1e3:g} µm pitch and the vernier at {v['vernier_pitch_nm'] / 1e3:g} µm, "
            f"reading ±{v['range_nm'] / 1e3:g} µm; each plate's sites are manifest.json's verniers.sites_m.")


def _dicing(man: dict) -> str:
    """The README's words on the keyed dicing outline (``doefab.diekey``), from the manifest."""
    c = man.get("die_chamfer_m") or 0.0
    if not c:
        return "."
    side = ">" if man.get("mirrored_x") else "<"
    return (f": dice along it. The two corners of the coded half (x {side} 0 in the layout) are chamfered, legs "
            f"{c * 1e3:g} mm at +y and {SECOND_CHAMFER * c * 1e3:g} mm at −y: they key the die in the holder's pocket "
            "(not turned, not flipped); the alignment keys they cut off are needed only until the last etch.")


def _windows(man: dict) -> str:
    """How an etch plate shows the keys it aligns to, for the set's resist tone (``marks.MarkSpec.windows``)."""
    negative = any(L.get("resist_tone") == "negative" for L in man["layers"] if L.get("purpose") == "etch")
    negative = negative and not drawn_before_3(man)  # such sets drew windows whatever the tone
    return ("is clear field, so the keys of the plate it aligns to show through clear glass" if negative else
            "opens a clear window over the keys of the plate it aligns to")


def fab_readme(man: dict) -> str:
    """``README.txt`` of a mask set: the manifest in words, for the fab (verification compares the two)."""
    n_levels = manifest_levels(man)
    first = man.get("format") == "doefab mask set 1"
    formats = "GDSII" if first else " and ".join(_FORMATS.get(k, k) for k in man["files"])
    view = man["mirror_means"] if first else man["mirror_means"][:1].upper() + man["mirror_means"][1:]
    lines = [
        "doefab mask set — instructions for the fab",
        "",
        f"Files: {', '.join(man['files'].values())} ({formats}, 1 nm database unit, 1 µm user unit), "
        "manifest.json (machine-readable), preview_*.png, report.json (verification).",
        f"Substrate: {man['material']['name']}{_thickness(man)}; design wavelength "
        f"{man['design_wavelength_m'] * 1e9:.0f} nm; "
        f"{n_levels} levels, step d = {man['level_step_nm']} nm.",
        f"Pixel pitch {man['pitch_m'] * 1e6:g} µm, {man['shape'][0]} x {man['shape'][1]} pixels; die "
        f"{man['die_m'] * 1e3:g} mm; clear aperture {man['clear_aperture_diameter_m'] * 1e3:g} mm.",
        "",
        "Layers (one plate each; keys on layer 10 and verniers/CD ladder on layer 11 carry the plate number "
        "as datatype and go on the same plate):",
    ]
    for L in man["layers"]:
        depth = f", etch depth {L['etch_depth_nm']} nm ± {L['etch_depth_tolerance_nm']} nm" if "etch_depth_nm" in L else ""
        lines.append(f"  layer {L['layer']} (plate {L['plate']}, step {L['process_step']}): {L['purpose']}{depth}; "
                     f"{L['polygons_mean']}; {L['mask_polarity']} for {L['resist_tone']} resist; "
                     + ("the first plate, aligned to no other." if L["aligns_to_plate"] is None else
                        f"aligns to plate {L['aligns_to_plate']}."))
    lines += [
        "",
        f"Process order: layer {' → '.join(str(x) for x in man['process_order'])}. The chrome plate is written "
        "first; alignment scheme: " + man["alignment_scheme"] + " (each etch plate " + _windows(man)
        + " and carries its own cross)." + _clear_fields(man) + _verniers(man),
        f"Level k = {n_levels - 1} − Σ 2^bit over the masks that etch the pixel; height = k·d above the deepest etch.",
        "The layout is drawn as seen from the patterned face. " + view + ".",
        "Layer 63 (labels) is reserved and not written. Layer 100 is the die outline" + _dicing(man),
    ]
    return "\n".join(lines) + "\n"
