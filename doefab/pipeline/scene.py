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
from doefab.applications import APPLICATIONS, View, has
from doefab.errors import DoefabError, problems_error
from doefab.io import read_toml
from doefab.pipeline.scenekeys import RENAMED, STAGES, item_text, keys_of, toml_value, values_text

__all__ = ["Scene", "load_scene", "check_scene", "TASK_DESIGN", "STAGES"]

TASK_DESIGN = View(lambda a: a.design_task)  # a view of the registry (read on every lookup), for callers
SECTIONS = ("camera", "sensor", "optics", "design", "fabrication", "holder", "reconstruction", "tolerance")
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
        """The tolerance budget file: None for the shipped default, else relative to the scene file (or absolute)."""
        from doefab.tolerance.errors import names_default_budget

        b = (self.tolerance or {}).get("budget", "default")
        return None if names_default_budget(b, self.path.parent) else scene_relative(self.path, b)

    def response_path(self) -> str:
        """``sensor.response``: a camera name as given, a CSV path relative to the scene file (or absolute)."""
        from doefab.imaging.responses import DEFAULT_RESPONSE, is_named

        r = self.sensor.get("response", DEFAULT_RESPONSE)
        return r if is_named(r) else str(scene_relative(self.path, r))

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
        return choice_problem(where, v, key.choices)
    if key.inf and distance_or_inf(v) == math.inf:  # inf, or "inf"
        return None
    if not _typed(v, key.kind):
        return _type_problem(where, v, key)
    if key.resolve is not None:
        try:
            key.resolve(v)
        except DoefabError as exc:
            return f"{where}: {exc}"
    if key.kind in ("float", "int") and key.lo is not None:
        if not math.isfinite(v) or not key.lo <= v <= key.hi:
            return f"{where} = {v} is outside {key.lo:g}–{key.hi:g} {key.unit}{_hint(v, key)}".rstrip()
    return None


_KIND_WORDS = {"float": "a number", "int": "a whole number", "str": "text in quotes", "bool": "true or false"}


def _type_problem(where: str, v, key) -> str:
    """A value of the wrong type: what the key takes, and the line to write where the value is a number in quotes
    or with its unit (``"35 mm"``: the unit is in the key's name)."""
    what = _KIND_WORDS.get(key.kind, key.kind) + (" or inf" if key.inf else "")
    text = f"{where} must be {what}, got {v!r}"
    if key.kind in ("float", "int") and isinstance(v, str):
        number, _, unit = v.strip().partition(" ")
        try:
            x = float(number)
        except ValueError:
            return text
        same = unit.strip() in ("", key.unit, key.unit.replace("µ", "u"))
        if math.isfinite(x) and same and (key.kind == "float" or x.is_integer()):
            named = f" (the unit, {key.unit}, is in the key's name)" if key.unit else ""
            return text + f": write {where.split('.')[-1]} = {number} without quotes{named}"
        if key.unit and not same:
            return text + f": write the number in {key.unit}, without quotes (the unit is in the key's name)"
    if key.kind == "int" and isinstance(v, float) and v.is_integer():
        return text + f": write {int(v)}"
    return text


def choice_problem(where: str, v, choices) -> str | None:
    """The problem with a choice key's value (None: it is one of ``choices``, of the same type: 8.0 is not 8),
    naming the choice meant where only case or spaces differ."""
    if any(v == c and type(v) is type(c) for c in choices):
        return None
    listed = ", ".join(map(str, choices))
    if v is None:
        return f"{where} is missing: add {where} = {toml_value(choices[0])} (one of {listed})"
    near = [c for c in choices if str(c).lower() == str(v).strip().lower() or (v == c and not isinstance(v, bool))]
    if near and (isinstance(v, str) or not isinstance(near[0], str)):
        return f"{where} {v!r} is not one of {listed}: write {where.split('.')[-1]} = {toml_value(near[0])}"
    return f"{where} {v!r} is not one of {listed}"


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
    task = raw.get("task") if isinstance(raw.get("task"), str) else None
    for key, val in raw.items():
        if key in SECTIONS and not isinstance(val, dict):
            problems.append(_not_table(key, val))
        elif isinstance(val, dict) and key not in keys_of(""):  # (a top-level key's table: its check names it)
            if key not in SECTIONS:
                problems.append(f"unknown section [{key}]")
            elif key != "holder":
                known = keys_of(key)
                for k, v in val.items():
                    if (key, k) in RENAMED:
                        problems.append(_renamed(key, k, v, val))
                    elif k not in known:
                        problems.append(f"unknown key {key}.{k}")
                    elif known[k].only and task in APPLICATIONS and not has(task, known[k].only):
                        problems.append(_other_task(f"{key}.{k}", known[k].only, task))
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


def _not_table(section: str, value) -> str:
    """A known section given as a value, or as an array of tables (``[[holder]]``)."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return f"[[{section}]] is an array of tables: write [{section}] once, with its keys under it"
    return (f"{section} = {value!r}: [{section}] is a table: write [{section}] on a line of its own, with its keys "
            f"under it")


def _other_task(where: str, prop: str, task: str) -> str:
    """A key of another application's scenes (``Key.only``): which tasks take it."""
    takers = [n for n in APPLICATIONS if has(n, prop)]
    return (f"{where} applies to task = {' or '.join(map(repr, takers))} only (this scene's task is {task!r}): "
            f"delete it")


def _key_problems(raw: dict, stages: tuple) -> list[str]:
    """Every key's problems (``_schema_problems``), the task's and the stages' (``_stage_problems``)."""
    task = choice_problem("task", raw.get("task"), tuple(APPLICATIONS))
    return _schema_problems(raw) + ([task] if task else []) + _stage_problems(stages)


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
    if not raw:
        raise DoefabError(f"scene file {p} holds no keys: `doefab scene new --task TASK --out FILE` writes one with "
                          f"every key to edit")
    task = raw.get("task")
    stages = raw.get("stages", STAGES)
    stages = tuple(stages) if isinstance(stages, list) else STAGES  # not a list: named by the schema check
    problems = _key_problems(raw, stages)
    cam, opt, des, fab, hol, rec, sen = (_table(raw, s) for s in ("camera", "optics", "design", "fabrication",
                                                                    "holder", "reconstruction", "sensor"))
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
    if "size_px" in rec and _typed(rec["size_px"], "int") and rec["size_px"] % 32:
        problems.append(f"reconstruction.size_px = {rec['size_px']} must be a multiple of 32")
    tol = raw.get("tolerance") if isinstance(raw.get("tolerance"), dict) else None
    if tol is not None:
        problems += _budget_problems(p, tol.get("budget", "default"))
        from doefab.tolerance.schedulers import runner_conflict

        both = runner_conflict(tol.get("workers"), tol.get("scheduler"), ("tolerance.workers", "tolerance.scheduler"))
        problems += [both] if both else []
    if problems:
        raise problems_error(p, problems)
    return Scene(path=p, task=task, stages=stages, camera=cam, optics=opt, design=des, fabrication=fab, holder=hol,
                 reconstruction=rec, tolerance=tol, sensor=sen, raw=raw, device=raw.get("device"))


def check_scene(scene: Scene) -> None:
    """A ``Scene`` built in code checked as ``load_scene`` checks a file (every key's type, unit, range and choice,
    keys of another task, the stages): one DoefabError listing the problems, none for a scene ``load_scene`` made.

    Example: ``check_scene(Scene(path=Path("my.toml"), task="hdr", stages=STAGES, camera={"focal_lenght_mm": 35}))``
    raises "unknown key camera.focal_lenght_mm"."""
    raw = {"task": scene.task, "stages": list(scene.stages),
           **{name: getattr(scene, name) for name in SECTIONS if getattr(scene, name)}}
    if scene.device is not None:
        raw["device"] = scene.device
    problems = _key_problems(raw, tuple(scene.stages))
    if problems:
        raise problems_error(scene.path, problems)


def _table(raw: dict, section: str) -> dict:
    """A section of the file ({} where it is missing, or not a table: ``_not_table`` names that)."""
    v = raw.get(section, {})
    return v if isinstance(v, dict) else {}


def scene_relative(scene_path: Path, given: str) -> Path:
    """A path a scene file names: relative to the scene file's folder (wherever the command runs), or absolute.

    Example: ``scene_relative(Path("scenes/a.toml"), "b.toml")`` → ``Path("scenes/b.toml")``."""
    return scene_path.parent / Path(given).expanduser()


def _budget_problems(scene_path: Path, budget) -> list[str]:
    """The problems of the tolerance budget a scene names (every key's range, the spec's limits), each named
    ``tolerance.budget FILE: ...``: a bad budget is refused with the scene, before any stage runs."""
    from doefab.tolerance.errors import budget_problems, names_default_budget

    if not isinstance(budget, str) or names_default_budget(budget, scene_path.parent):
        return []  # the shipped budget; a value of another type is named by the schema check
    path = scene_relative(scene_path, budget)
    if path.is_dir():
        return [f"tolerance.budget {budget!r}: {path} is a folder: give a budget TOML file (or default)"]
    if not path.is_file():
        return [f"tolerance.budget {budget!r}: no file at {path} (a path relative to the scene file, or absolute; or "
                f"default)"]
    try:
        return [f"tolerance.budget {budget}: {q}" for q in budget_problems(path)]
    except DoefabError as exc:  # not TOML
        return [f"tolerance.budget: {exc}"]
