"""Scene files (TOML): what the user wants, validated as a whole before any work starts.

Every key, its unit and default (the documentation's scene page shows this table):

| key | unit | default |
| --- | --- | --- |
| ``task`` | hdr, hyperspectral or depth | required |
| ``stages`` | list of design, masks, holder, reconstruction, tolerance, report | all |
| ``camera.preset`` | default, hdr, hyperspectral, depth | the task's (hdr, hyperspectral, depth) |
| ``camera.focus_distance_m`` | m | the preset's |
| ``camera.sensor_distance_m`` | m | the preset's |
| ``optics.wavelengths_nm`` | nm, 300–1100 | the task's (RGB 656/589/486, or 400–700 every 10) |
| ``optics.depths_m`` | m, > 0 | the task's (focus distance, or 1–5 m every 0.25) |
| ``optics.kernel_px`` | sensor pixels | the task's (95, 191, 63) |
| ``design.optimizer`` | adam, lbfgs, mma | the committed design's |
| ``design.iterations`` | steps | the committed design's |
| ``design.sampling`` | DOE pixels per design pixel | the committed design's |
| ``design.seed`` | — | 0 |
| ``design.parameterization`` | pixel or radial | the committed design's |
| ``design.knots`` | radial knots (0 = one per DOE pixel along the radius) | the committed design's |
| ``design.ring_law`` | half-ring only: seed or defocus | the committed design's |
| ``fabrication.levels`` | 16 (4 binary masks) | 16 |
| ``fabrication.material`` | fused silica | fused silica |
| ``fabrication.pattern_faces`` | lens or scene | lens |
| ``fabrication.oasis`` | true/false | false |
| ``holder.<name>_mm`` etc. | any ``doefab holder --set`` parameter | holder defaults |
| ``reconstruction.weights`` | shipped or train | shipped |
| ``reconstruction.minutes`` | minutes of training (weights = train) | 6 |
| ``reconstruction.images`` / ``size_px`` | test scenes / pixels (multiple of 32) | 4 / 256 |
| ``tolerance.budget`` | default or a TOML path | absent: no Monte Carlo |
| ``tolerance.samples`` | parts | 20 |
| ``tolerance.supersample`` | grid refinement | 1 |
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from doefab._validate import metres_hint
from doefab.errors import DoefabError
from doefab.io import read_toml

__all__ = ["Scene", "load_scene", "TASK_DESIGN", "STAGES"]

TASK_DESIGN = {"hdr": "streak", "hyperspectral": "grating", "depth": "half-ring"}
STAGES = ("design", "masks", "holder", "reconstruction", "tolerance", "report")
_SCHEMA = {
    "": {"task": str, "stages": list},
    "camera": {"preset": str, "focus_distance_m": float, "sensor_distance_m": float},
    "optics": {"wavelengths_nm": list, "depths_m": list, "kernel_px": int},
    "design": {"optimizer": str, "iterations": int, "sampling": int, "seed": int, "parameterization": str,
               "knots": int, "ring_law": str},
    "fabrication": {"levels": int, "material": str, "pattern_faces": str, "oasis": bool},
    "holder": None,  # checked against HolderParams
    "reconstruction": {"weights": str, "minutes": float, "images": int, "size_px": int},
    "tolerance": {"budget": str, "samples": int, "supersample": int},
}


@dataclass
class Scene:
    path: Path
    task: str
    stages: tuple
    camera: dict = field(default_factory=dict)
    optics: dict = field(default_factory=dict)
    design: dict = field(default_factory=dict)
    fabrication: dict = field(default_factory=dict)
    holder: dict = field(default_factory=dict)
    reconstruction: dict = field(default_factory=dict)
    tolerance: dict | None = None
    raw: dict = field(default_factory=dict)

    def budget_path(self) -> Path | None:
        """The tolerance budget file: None for the shipped default, else relative to the scene file or as given."""
        b = (self.tolerance or {}).get("budget", "default")
        if b == "default":
            return None
        return self.path.parent / b if (self.path.parent / b).is_file() else Path(b)

    def section(self, name: str) -> dict:
        return self.raw.get(name, {}) if name else {k: v for k, v in self.raw.items() if not isinstance(v, dict)}


def _typed(v, typ) -> bool:
    if typ is float:
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    if typ is int:
        return isinstance(v, int) and not isinstance(v, bool)
    return isinstance(v, typ)


def _schema_problems(raw: dict) -> list[str]:
    """Unknown sections and keys, and values of the wrong type."""
    problems = []
    for key, val in raw.items():
        if isinstance(val, dict):
            if key not in _SCHEMA or key == "":
                problems.append(f"unknown section [{key}]")
                continue
            schema = _SCHEMA[key]
            if schema is None:
                continue
            for k, v in val.items():
                if k not in schema:
                    problems.append(f"unknown key {key}.{k}")
                elif not _typed(v, schema[k]):
                    problems.append(f"{key}.{k} must be {schema[k].__name__}, got {v!r}")
        elif key not in _SCHEMA[""]:
            problems.append(f"unknown key {key}")
        elif not _typed(val, _SCHEMA[""][key]):
            problems.append(f"{key} must be {_SCHEMA[''][key].__name__}")
    return problems


def _stage_problems(stages: tuple) -> list[str]:
    """Unknown stages, and stages listed without the design stage they need."""
    problems = [f"stages: unknown stage {s!r} (choose from {list(STAGES)})" for s in stages if s not in STAGES]
    needy = [s for s in ("masks", "reconstruction", "tolerance") if s in stages and "design" not in stages]
    if needy:
        problems.append(f"stages: {', '.join(needy)} need{'s' if len(needy) == 1 else ''} the design stage: add "
                        f"\"design\" to stages")
    return problems


def load_scene(path: str | Path) -> Scene:
    """Read a scene file; every problem (unknown key, wrong type or unit, impossible value) in one message."""
    p = Path(path)
    raw = read_toml(p, "scene file")
    problems = _schema_problems(raw)
    task = raw.get("task")
    if task not in TASK_DESIGN:
        problems.append(f"task must be one of {sorted(TASK_DESIGN)}, got {task!r}")
    stages = tuple(raw.get("stages", STAGES))
    problems += _stage_problems(stages)
    cam = raw.get("camera", {})
    if "preset" in cam and cam["preset"] not in ("default", "hdr", "hyperspectral", "depth"):
        problems.append(f"camera.preset {cam['preset']!r} is not one of default, hdr, hyperspectral, depth")
    for k, lo, hi in (("focus_distance_m", 1e-3, 1e6), ("sensor_distance_m", 1e-3, 2.0)):
        if k in cam and _typed(cam[k], float) and not lo <= cam[k] <= hi:
            hint = metres_hint(cam[k], lo, hi) if math.isfinite(cam[k]) else ""
            problems.append(f"camera.{k} = {cam[k]} is outside {lo:g}–{hi:g} m{hint}")
    opt = raw.get("optics", {})
    lams = opt.get("wavelengths_nm", []) if isinstance(opt.get("wavelengths_nm", []), list) else []
    bad = [w for w in lams if not _typed(w, float) or not 300 <= w <= 1100]
    if bad:
        metres = [w for w in bad if _typed(w, float) and 0 < w < 1]
        hint = f" ({metres[0]!r} looks like metres: write {metres[0] * 1e9:.4g}, not {metres[0]!r})" if metres else ""
        problems.append(f"optics.wavelengths_nm holds {', '.join(map(repr, bad))}: wavelengths are nm within "
                        f"300–1100{hint}")
    for z in opt.get("depths_m", []) if isinstance(opt.get("depths_m", []), list) else []:
        if not (z == "inf" or (_typed(z, float) and z > 0 and math.isfinite(z))):
            problems.append(f"optics.depths_m holds {z!r}: depths are metres > 0 (or \"inf\")")
    if "kernel_px" in opt and _typed(opt["kernel_px"], int) and not 15 <= opt["kernel_px"] <= 1023:
        problems.append(f"optics.kernel_px = {opt['kernel_px']} must be 15–1023 sensor pixels")
    des = raw.get("design", {})
    if "optimizer" in des and des["optimizer"] not in ("adam", "lbfgs", "mma"):
        problems.append(f"design.optimizer {des['optimizer']!r} is not adam, lbfgs or mma")
    for k, lo, hi in (("iterations", 1, 100000), ("sampling", 1, 16), ("seed", 0, 2**32 - 1), ("knots", 0, 100000)):
        if k in des and _typed(des[k], int) and not lo <= des[k] <= hi:
            problems.append(f"design.{k} = {des[k]} must be {lo}–{hi}")
    fab = raw.get("fabrication", {})
    if fab.get("levels", 16) != 16:
        problems.append("fabrication.levels: the mask process makes 16 levels (4 binary masks); other counts are "
                        "a tolerance study (doefab tolerance --levels), not a fabrication")
    if fab.get("material", "fused silica") not in ("fused silica", "fused_silica"):
        problems.append(f"fabrication.material {fab['material']!r}: only fused silica is built in")
    if fab.get("pattern_faces", "lens") not in ("lens", "scene"):
        problems.append("fabrication.pattern_faces must be lens or scene")
    hol = raw.get("holder", {})
    if hol:
        import dataclasses

        from holder_cad.params import HolderError, HolderParams

        names = {f.name for f in dataclasses.fields(HolderParams)}
        bad = [k for k in hol if k not in names]
        problems += [f"unknown key holder.{k}" for k in bad]
        if not bad:
            try:
                HolderParams(**hol)
            except (HolderError, TypeError) as exc:
                problems.append(f"holder: {exc}")
    rec = raw.get("reconstruction", {})
    if rec.get("weights", "shipped") not in ("shipped", "train"):
        problems.append("reconstruction.weights must be shipped or train")
    if "size_px" in rec and _typed(rec["size_px"], int) and (rec["size_px"] % 32 or not 64 <= rec["size_px"] <= 2048):
        problems.append(f"reconstruction.size_px = {rec['size_px']} must be a multiple of 32 in 64–2048")
    if "images" in rec and _typed(rec["images"], int) and not 1 <= rec["images"] <= 10000:
        problems.append(f"reconstruction.images = {rec['images']} must be 1–10000 test scenes")
    if "minutes" in rec and _typed(rec["minutes"], float) and not 0 < rec["minutes"] <= 600:
        problems.append("reconstruction.minutes must be in (0, 600]")
    tol = raw.get("tolerance")
    if tol is not None:
        b = tol.get("budget", "default")
        if b != "default" and not (p.parent / b).is_file() and not Path(b).is_file():
            problems.append(f"tolerance.budget {b!r}: no such file (give default or a TOML path)")
        if "samples" in tol and _typed(tol["samples"], int) and not 0 <= tol["samples"] <= 100000:
            problems.append("tolerance.samples must be 0–100000")
        if "supersample" in tol and _typed(tol["supersample"], int) and not 1 <= tol["supersample"] <= 8:
            problems.append("tolerance.supersample must be 1–8")
    if problems:
        raise DoefabError(f"{p}: {len(problems)} problem(s): " + "; ".join(problems))
    return Scene(path=p, task=task, stages=stages, camera=cam, optics=opt, design=des, fabrication=fab, holder=hol,
                 reconstruction=rec, tolerance=tol, raw=raw)
