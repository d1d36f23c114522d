"""Scene files (TOML): what the user wants, validated as a whole before any work starts.

Every key, its type, unit, range and default are in ``scenekeys.KEYS`` (the documentation's scene-key
reference and ``doefab scene new``'s template are made from the same table). ``load_scene`` checks every key
against it and lists every problem with its key; the physics of the system a scene describes (does the DOE grid
cover the aperture, does the fab resolve the DOE pixel, do the grating's orders fit the window...) is checked by
``system.resolve`` before any folder is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from doefab._validate import metres_hint, unit_hint
from doefab.errors import DoefabError
from doefab.io import read_toml

__all__ = ["Scene", "load_scene", "TASK_DESIGN", "STAGES"]

TASK_DESIGN = {"hdr": "streak", "hyperspectral": "grating", "depth": "half-ring"}
STAGES = ("design", "masks", "holder", "reconstruction", "tolerance", "report")
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
    sensor: dict = field(default_factory=dict)
    raw: dict = field(default_factory=dict)

    def budget_path(self) -> Path | None:
        """The tolerance budget file: None for the shipped default, else relative to the scene file or as given."""
        b = (self.tolerance or {}).get("budget", "default")
        if b == "default":
            return None
        return self.path.parent / b if (self.path.parent / b).is_file() else Path(b)

    def response_path(self) -> str:
        """``sensor.response``: a camera name as given, a CSV path relative to the scene file (or as given)."""
        from doefab.imaging.responses import DEFAULT_RESPONSE, is_named

        r = self.sensor.get("response", DEFAULT_RESPONSE)
        if is_named(r):
            return r
        return str(self.path.parent / r) if (self.path.parent / r).is_file() else r

    def section(self, name: str) -> dict:
        return self.raw.get(name, {}) if name else {k: v for k, v in self.raw.items() if not isinstance(v, dict)}


def _typed(v, kind: str) -> bool:
    if kind == "float":
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    if kind == "int":
        return isinstance(v, int) and not isinstance(v, bool)
    return isinstance(v, {"str": str, "bool": bool, "list": list}.get(kind, object))


def _value_problem(where: str, v, key) -> str | None:
    """The problem with one value of a known key, or None."""
    if key.kind == "choice":
        return None if v in key.choices else f"{where} {v!r} is not one of {', '.join(map(str, key.choices))}"
    if not _typed(v, key.kind):
        return f"{where} must be {'a number' if key.kind == 'float' else key.kind}, got {v!r}"
    if key.kind in ("float", "int") and key.lo is not None:
        if not math.isfinite(v) or not key.lo <= v <= key.hi:
            hint = "" if not math.isfinite(v) else (metres_hint(v, key.lo, key.hi) if key.unit == "m" else
                                                     unit_hint(v, key.lo, key.hi, key.unit))
            return f"{where} = {v} is outside {key.lo:g}–{key.hi:g} {key.unit}{hint}".rstrip()
    return None


def _schema_problems(raw: dict) -> list[str]:
    """Unknown sections and keys, values of the wrong type, choice or range (``scenekeys.KEYS``)."""
    from doefab.pipeline.scenekeys import keys_of

    problems = []
    sections = {"camera", "sensor", "optics", "design", "fabrication", "holder", "reconstruction", "tolerance"}
    for key, val in raw.items():
        if isinstance(val, dict):
            if key not in sections:
                problems.append(f"unknown section [{key}]")
            elif key != "holder":
                known = keys_of(key)
                for k, v in val.items():
                    if k not in known:
                        problems.append(f"unknown key {key}.{k}")
                    elif known[k].kind != "list":
                        problems.append(_value_problem(f"{key}.{k}", v, known[k]))
        elif key not in keys_of(""):
            problems.append(f"unknown key {key}")
    cam = raw.get("camera", {}) if isinstance(raw.get("camera"), dict) else {}
    for a, b in (("focal_length_mm", "sensor_distance_mm"), ("aperture_diameter_mm", "f_number"),
                 ("sensor_distance_mm", "sensor_distance_m")):
        if a in cam and b in cam:
            problems.append(f"camera.{a} and camera.{b} say the same thing: give one of them")
    return [p for p in problems if p]


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
    opt = raw.get("optics", {})
    lams = opt.get("wavelengths_nm", []) if isinstance(opt.get("wavelengths_nm", []), list) else []
    bad = [w for w in lams if not _typed(w, "float") or not 300 <= w <= 1100]
    if bad:
        metres = [w for w in bad if _typed(w, "float") and 0 < w < 1]
        hint = f" ({metres[0]!r} looks like metres: write {metres[0] * 1e9:.4g}, not {metres[0]!r})" if metres else ""
        problems.append(f"optics.wavelengths_nm holds {', '.join(map(repr, bad))}: wavelengths are nm within "
                        f"300–1100{hint}")
    for z in opt.get("depths_m", []) if isinstance(opt.get("depths_m", []), list) else []:
        if not (z == "inf" or (_typed(z, "float") and z > 0 and math.isfinite(z))):
            problems.append(f"optics.depths_m holds {z!r}: depths are metres > 0 (or \"inf\")")
    des = raw.get("design", {})
    fab = raw.get("fabrication", {})
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
    if "size_px" in rec and _typed(rec["size_px"], "int") and rec["size_px"] % 32:
        problems.append(f"reconstruction.size_px = {rec['size_px']} must be a multiple of 32")
    tol = raw.get("tolerance")
    if tol is not None:
        b = tol.get("budget", "default")
        if b != "default" and not (p.parent / b).is_file() and not Path(b).is_file():
            problems.append(f"tolerance.budget {b!r}: no such file (give default or a TOML path)")
    if problems:
        raise DoefabError(f"{p}: {len(problems)} problem(s): " + "; ".join(problems))
    return Scene(path=p, task=task, stages=stages, camera=cam, optics=opt, design=des, fabrication=fab, holder=hol,
                 reconstruction=rec, tolerance=tol, sensor=raw.get("sensor", {}), raw=raw)
