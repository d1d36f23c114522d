"""Scene files (TOML): what the user wants, validated as a whole before any work starts.

Every key, its type, unit, range and default are in ``scenekeys.KEYS`` (the documentation's scene-key
reference and ``doefab scene new``'s template are made from the same table). ``load_scene`` checks every key
against it (each item of a list key too) and the tolerance budget the scene names (every range of
``tolerance.errors.budget_problems``), and lists every problem with its key; the physics of the system a scene
describes (does the DOE grid cover the aperture, does the fab resolve the DOE pixel, do the grating's orders
fit the window...) is checked by ``system.resolve`` before any folder is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from doefab.validate import distance_or_inf, metres_hint, unit_hint
from doefab.applications import APPLICATIONS, View
from doefab.errors import DoefabError
from doefab.io import read_toml
from doefab.pipeline.scenekeys import RENAMED, STAGES, item_text, keys_of, toml_value, values_text

__all__ = ["Scene", "load_scene", "TASK_DESIGN", "STAGES"]

TASK_DESIGN = View(lambda a: a.design_task)  # a view of the registry (read on every lookup), for callers
# keys that set the same quantity: a scene gives at most one of each group
SAME_QUANTITY = ((("focal_length_mm", "sensor_distance_mm", "sensor_distance_m"), "the lens-to-sensor distance"),
                 (("aperture_diameter_mm", "f_number"), "the DOE's aperture"))


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
    device: str | None = None  # the scene's device key (None: not given, the default device)

    def budget_path(self) -> Path | None:
        """The tolerance budget file: None for the shipped default, else relative to the scene file or as given."""
        b = (self.tolerance or {}).get("budget", "default")
        return None if b == "default" else _budget_file(self.path, b)

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


def _hint(v: float, key) -> str:
    """The unit slip a value outside a key's range suggests (" (550 nm is 5.5e-07 m)"), or ''."""
    if not math.isfinite(v):
        return ""
    return metres_hint(v, key.lo, key.hi) if key.unit == "m" else unit_hint(v, key.lo, key.hi, key.unit)


def _value_problem(where: str, v, key) -> str | None:
    """The problem with one value of a known key, or None."""
    if key.kind == "list":
        return _list_problem(where, v, key)
    if key.kind == "choice":
        if key.resolve is not None:
            try:
                key.resolve(v)
            except DoefabError as exc:
                return f"{where}: {exc}"
            return None
        return None if v in key.choices else f"{where} {v!r} is not one of {', '.join(map(str, key.choices))}"
    if key.inf and distance_or_inf(v) == math.inf:  # inf, or "inf"
        return None
    if not _typed(v, key.kind):
        what = "a number" + (" or inf" if key.inf else "") if key.kind == "float" else key.kind
        return f"{where} must be {what}, got {v!r}"
    if key.resolve is not None:
        try:
            key.resolve(v)
        except DoefabError as exc:
            return f"{where}: {exc}"
    if key.kind in ("float", "int") and key.lo is not None:
        if not math.isfinite(v) or not key.lo <= v <= key.hi:
            return f"{where} = {v} is outside {key.lo:g}–{key.hi:g} {key.unit}{_hint(v, key)}".rstrip()
    return None


def _bad_item(x, key) -> bool:
    """Whether one item of a list key is outside what the key's items take."""
    if x in key.choices and isinstance(x, str):
        return False
    if key.inf and distance_or_inf(x) == math.inf:  # inf, or "inf", as a float key takes it
        return False
    if key.item == "choice":
        return True
    return not _typed(x, key.item) or not math.isfinite(x) or not key.lo <= x <= key.hi


def _list_problem(where: str, v, key) -> str | None:
    """The problems with a list key's value: not a list, empty, items outside what the key's items take, an item
    given twice."""
    if not isinstance(v, list):
        fix = f": write [{toml_value(v)}]" if not _bad_item(v, key) else f" ({values_text(key)})"
        return f"{where} must be a list{fix}"
    if not v:
        return f"{where} is empty: list at least one item ({item_text(key)}), or leave it out for {key.default}"
    problems = []
    bad = [x for x in v if _bad_item(x, key)]
    if bad:
        hint = next((h for x in bad if _typed(x, "float") for h in [_hint(x, key)] if h), "")
        problems.append(f"{where} holds {', '.join(map(repr, bad))}: each item must be {item_text(key)}{hint}")
    same = [distance_or_inf(x) if key.inf and distance_or_inf(x) is not None else x for x in v]  # inf is "inf"
    twice = [math.inf if same[i] == math.inf else x for i, x in enumerate(v) if same[i] in same[:i]]
    spellings = {repr(x) for x, s in zip(v, same) if s == math.inf}
    also = f" ({' and '.join(sorted(spellings))} are one plane)" if len(spellings) > 1 else ""
    if twice:
        once = [x for i, x in enumerate(v) if same[i] not in same[:i]]
        problems.append(f"{where} holds {', '.join(map(repr, dict.fromkeys(twice)))} more than once{also}: list each "
                        f"item once, e.g. {toml_value(once)}")
    return "; ".join(problems) or None


def _renamed(section: str, old: str, value, table: dict) -> str:
    """The problem of a key under its earlier name (``scenekeys.RENAMED``): the line to write instead, or to delete
    when the table holds the new name too; a value the new key refuses is named with it."""
    new = RENAMED[section, old]
    if new in table:
        return f"{section}.{old} is now {section}.{new}, which this file sets too: delete {old}"
    why = _value_problem(f"{section}.{new}", value, keys_of(section)[new])
    if why:
        return f"{section}.{old} is now {section}.{new}, and {why}"
    return f"{section}.{old} is now {section}.{new}: write {new} = {value!r} in [{section}]"


def _schema_problems(raw: dict) -> list[str]:
    """Unknown sections and keys, values of the wrong type, choice or range (``scenekeys.KEYS``), keys that set
    the same quantity twice."""
    problems = []
    sections = {"camera", "sensor", "optics", "design", "fabrication", "holder", "reconstruction", "tolerance"}
    for key, val in raw.items():
        if isinstance(val, dict):
            if key not in sections:
                problems.append(f"unknown section [{key}]")
            elif key != "holder":
                known = keys_of(key)
                for k, v in val.items():
                    if (key, k) in RENAMED:
                        problems.append(_renamed(key, k, v, val))
                    elif k not in known:
                        problems.append(f"unknown key {key}.{k}")
                    else:
                        problems.append(_value_problem(f"{key}.{k}", v, known[k]))
        elif key not in keys_of(""):
            problems.append(f"unknown key {key}")
        elif key != "task":
            problems.append(_value_problem(key, val, keys_of("")[key]))
    cam = raw.get("camera", {}) if isinstance(raw.get("camera"), dict) else {}
    for group, what in SAME_QUANTITY:
        given = [f"camera.{k} = {cam[k]!r}" for k in group if k in cam]
        if len(given) > 1:
            problems.append(f"{' and '.join(given)} both set {what}: keep one of them")
    return [p for p in problems if p]


def _stage_problems(stages: tuple) -> list[str]:
    """Stages listed without the design stage they need."""
    problems = []
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
    if task not in APPLICATIONS:
        problems.append(f"task must be one of {sorted(APPLICATIONS)}, got {task!r}")
    stages = raw.get("stages", STAGES)
    stages = tuple(stages) if isinstance(stages, list) else STAGES  # not a list: named by the schema check
    problems += _stage_problems(stages)
    cam = raw.get("camera", {})
    opt = raw.get("optics", {})
    des = raw.get("design", {})
    fab = raw.get("fabrication", {})
    hol = raw.get("holder", {})
    if hol:
        import dataclasses

        from holder_cad.params import HolderParams, given_problem

        names = {f.name for f in dataclasses.fields(HolderParams)}
        bad = [k for k in hol if k not in names]
        problems += [f"unknown key holder.{k}" for k in bad]
        problem = None if bad else given_problem(hol)  # each value alone; the holder as a whole, with the DOE's
        if problem:                                      # die and aperture, is checked by ``system.resolve``
            own = '; or leave "holder" out of stages (a holder of your own)' if "holder" in stages else ""
            problems.append(f"holder: {problem}{own}")
    rec = raw.get("reconstruction", {})
    if "size_px" in rec and _typed(rec["size_px"], "int") and rec["size_px"] % 32:
        problems.append(f"reconstruction.size_px = {rec['size_px']} must be a multiple of 32")
    tol = raw.get("tolerance")
    if isinstance(tol, dict):
        problems += _budget_problems(p, tol.get("budget", "default"))
        from doefab.tolerance.schedulers import runner_conflict

        both = runner_conflict(tol.get("workers"), tol.get("scheduler"), ("tolerance.workers", "tolerance.scheduler"))
        problems += [both] if both else []
    if problems:
        raise DoefabError(f"{p}: {len(problems)} problem(s): " + "; ".join(problems))
    return Scene(path=p, task=task, stages=stages, camera=cam, optics=opt, design=des, fabrication=fab, holder=hol,
                 reconstruction=rec, tolerance=tol, sensor=raw.get("sensor", {}), raw=raw, device=raw.get("device"))


def _budget_file(scene_path: Path, budget: str) -> Path:
    """A budget path relative to the scene file (or as given)."""
    return scene_path.parent / budget if (scene_path.parent / budget).is_file() else Path(budget)


def _budget_problems(scene_path: Path, budget) -> list[str]:
    """The problems of the tolerance budget a scene names (every key's range, the spec's limits), each named
    ``tolerance.budget FILE: ...``: a bad budget is refused with the scene, before any stage runs."""
    from doefab.tolerance.errors import budget_problems

    if budget == "default" or not isinstance(budget, str):
        return []  # the shipped budget; a value of another type is named by the schema check
    path = _budget_file(scene_path, budget)
    if not path.is_file():
        return [f"tolerance.budget {budget!r}: no such file (give default or a TOML path)"]
    try:
        return [f"tolerance.budget {budget}: {q}" for q in budget_problems(path)]
    except DoefabError as exc:  # not TOML
        return [f"tolerance.budget: {exc}"]
