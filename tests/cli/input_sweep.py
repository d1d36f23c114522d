"""The input sweep (issue 21, "Done when"): every subcommand and every name of the public API ``doefab.__all__``.

Each numeric argument is tried with NaN, a negative, zero, a value in the wrong unit and an absurd magnitude
(the kinds that are valid for an argument — a seed of 0, a zero edge bias — are listed as such, not tried);
each file or folder argument with a missing path, the wrong kind of path (a folder for a file, a file for a
folder), an empty and a corrupt one; each flag or scene key that takes a word, a switch or a text (issue 37)
with one it does not take, a value of the wrong type and an empty one, and each ``--out`` with an empty path,
a file, a folder of the user's and a path under a file. At the command line every case must give exit status 2
(3 for a mask set that fails verification) and one line naming the argument, with nothing created or changed
and no job started (the work guard ``no_work``); from the API a ``doefab.DoefabError`` naming the argument.

This module holds the tables and the checks; the tests are collected per subcommand, each file
``test_inputs_<subcommand>.py`` taking that subcommand's cases (``sweep``; a case's subcommand is the first word of
its id; ``scene`` is the scene file's keys and ``doefab scene``), and ``test_inputs_api.py`` the public API's.
"""

from __future__ import annotations

import functools
import shutil
from pathlib import Path

import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError

REPO = Path(__file__).resolve().parents[2]
NAN, NEG, ZERO, UNIT, BIG = "nan", "negative", "zero", "wrong unit", "absurd"
KINDS = (NAN, NEG, ZERO, UNIT, BIG)
VALID = "valid"  # this kind is a legitimate value of the argument: not an error case
NA = "n/a"  # the argument has no unit to get wrong


def _int(lo_ok_zero: bool = False, unit=NA):
    """The five kinds for an integer count (NaN and 1e12 are not integers; 10**12 is absurd)."""
    return {NAN: "nan", NEG: "-1", ZERO: VALID if lo_ok_zero else "0", UNIT: unit, BIG: str(10**12)}


def _float(zero_ok: bool = False, unit=NA, big: str = "1e12"):
    return {NAN: "nan", NEG: "-1", ZERO: VALID if zero_ok else "0", UNIT: unit, BIG: big}


SEED = {NAN: "nan", NEG: "-1", ZERO: VALID, UNIT: NA, BIG: str(2**64)}


class WorkStarted(BaseException):
    """Raised where a command creates its output folder or computes PSFs: it accepted the input."""


@pytest.fixture
def no_work(monkeypatch):
    """The work guard of every command-line case: a command that claims its output folder or computes PSFs has
    started its job, so a case whose input gets through fails at once (WorkStarted) instead of designing or
    training. Returns a function that guards one more step (``module, name``)."""
    from doefab.io import OutputDir
    from doefab.optics.psf import PSFPlan

    def started(*args, **kwargs):
        raise WorkStarted("the command started its job instead of refusing the input")

    monkeypatch.setattr(OutputDir, "create", started)
    monkeypatch.setattr(PSFPlan, "__call__", started)
    return lambda module, name: monkeypatch.setattr(module, name, started)


# ---------------------------------------------------------------- command line: numeric flags
# (subcommand and the arguments it needs, flag, {kind: value}); "--out OUT" is added where the command has one
STREAK, GRATING = ["design", "--task", "streak"], ["design", "--task", "grating"]
FLAGS = [
    (["demo"], "--kernel", _int()),
    (["psf"], "--wavelengths-nm", {NAN: "nan", NEG: "-550", ZERO: "0", UNIT: "5.5e-7", BIG: "1e12"}),
    (["psf"], "--depths-m", {NAN: "nan", NEG: "-2", ZERO: "0", UNIT: NA, BIG: "1e12"}),
    (["psf"], "--kernel", _int()),
    (["psf"], "--pupil-oversample", _int()),
    (STREAK, "--iterations", _int()),
    (STREAK, "--lr", _float()),
    (STREAK, "--seed", SEED),
    (GRATING, "--sampling", _int()),
    (STREAK, "--batch", {NAN: "nan", NEG: "-2", ZERO: VALID, UNIT: NA, BIG: str(10**12)}),
    (STREAK, "--qat-fraction", _float(zero_ok=True, unit="20")),  # a percentage for a fraction
    (STREAK, "--fab-weight", _float(zero_ok=True)),
    (STREAK, "--checkpoint-every", _int()),
    (STREAK + ["--parameterization", "radial"], "--knots", _int()),
    (["masks", "--design", "{design}"], "--die-mm", _float(unit="0.012")),  # metres for millimetres
    (["masks", "--design", "{design}"], "--cd-um", _float(unit="5.4e-6")),
    (["masks", "--design", "{design}"], "--vertex-cap", _int()),
    (["train", "--task", "hdr"], "--minutes", _float(unit="36000")),  # seconds for minutes
    (["train", "--task", "hdr"], "--seed", SEED),
    (["train", "--task", "hdr"], "--batch", _int()),
    (["train", "--task", "hdr"], "--crop", _int()),
    (["train", "--task", "hdr"], "--lr", _float()),
    (["evaluate", "--task", "hdr"], "--images", _int()),
    (["evaluate", "--task", "hdr"], "--size", _int()),
    (["train", "--task", "hdr"], "--full-well-e", _float()),
    (["train", "--task", "hdr"], "--read-noise-e", _float(zero_ok=True)),
    (["evaluate", "--task", "hdr"], "--full-well-e", _float()),
    (["evaluate", "--task", "hdr"], "--read-noise-e", _float(zero_ok=True)),
    (["finetune", "--design", "{design}"], "--full-well-e", _float()),
    (["finetune", "--design", "{design}"], "--read-noise-e", _float(zero_ok=True)),
    (STREAK, "--n-levels", {NAN: "nan", NEG: "-16", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    (["finetune", "--design", "{design}"], "--minutes", _float(unit="36000")),
    (["finetune", "--design", "{design}"], "--doe-every", _int()),
    (["finetune", "--design", "{design}"], "--lr-doe", _float()),
    (["finetune", "--design", "{design}"], "--lr-net", _float()),
    (["finetune", "--design", "{design}"], "--sampling", _int()),
    (["finetune", "--design", "{design}"], "--seed", SEED),
    (["tolerance", "--design", "{design}"], "--samples", _int(lo_ok_zero=True)),
    (["tolerance", "--design", "{design}"], "--seed", SEED),
    (["tolerance", "--design", "{design}"], "--supersample", _int()),
    (["tolerance", "--design", "{design}"], "--workers", _int()),
    (["tolerance", "--design", "{design}"], "--grid", _int()),
    (["train", "--task", "hdr"], "--steps", _int()),
    (["masks", "--design", "{design}"], "--etch-order", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: "1000"}),
    (["tolerance", "--design", "{design}"], "--scheduler",
     {NAN: "local:nan", NEG: "local:-1", ZERO: "local:0", UNIT: NA, BIG: f"local:{10**12}"}),
]

def _holder_rows():
    """Every holder parameter (millimetres); the wrong unit is its default written in metres."""
    from holder_cad.params import HolderParams

    p = HolderParams()
    rows = [(name, {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: f"{getattr(p, name) / 1000:g}", BIG: "1e9"})
            for name in p.to_dict() if name.endswith("_mm")]
    return rows + [("segments", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: str(10**12)})]


def _expand(rows, make):
    out = []
    for row in rows:
        for kind in KINDS:
            value = row[-1][kind]
            if value not in (VALID, NA):
                out.append(pytest.param(*make(row, value), id=f"{make(row, value)[0]}-{kind}"))
    return out


FLAG_CASES = _expand(FLAGS, lambda row, value: (f"{row[0][0]} {row[1]}", row[0], row[1], value))
HOLDER_CASES = _expand(_holder_rows(), lambda row, value: (f"holder {row[0]}", row[0], value))


def _fill(args, fixtures):
    return [str(fixtures / "design") if a == "{design}" else a for a in args]


@pytest.mark.parametrize("name, cmd, flag, value", FLAG_CASES)
def test_numeric_flag(name, cmd, flag, value, one_clear_error, no_work):
    one_clear_error(lambda f, t: _fill(cmd, f) + [flag, value, "--out", t / "o"], 2, flag)


@pytest.mark.parametrize("name, param, value", HOLDER_CASES)
def test_holder_parameter(name, param, value, one_clear_error, no_work):
    one_clear_error(lambda f, t: ["holder", "--out", t / "o", "--set", f"{param}={value}"], 2, param)


# ---------------------------------------------------------------- command line: scene keys (run and doctor)
# (section, key, {kind: TOML value}); the scene is scenes/hdr.toml with the key set
SCENE_KEYS = [
    ("camera", "focus_distance_m", {NAN: "nan", NEG: "-5.0", ZERO: "0.0", UNIT: NA, BIG: "1e12"}),
    ("camera", "sensor_distance_m", {NAN: "nan", NEG: "-0.05", ZERO: "0.0", UNIT: "50.0", BIG: "1e12"}),
    ("optics", "wavelengths_nm", {NAN: "[nan]", NEG: "[-656.0]", ZERO: "[0.0]", UNIT: "[6.56e-7]", BIG: "[1e12]"}),
    ("optics", "depths_m", {NAN: "[nan]", NEG: "[-5.0]", ZERO: "[0.0]", UNIT: "[5000.0]", BIG: "[1e12]"}),
    ("optics", "kernel_px", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    ("design", "iterations", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    ("design", "sampling", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    ("design", "seed", {NAN: "nan", NEG: "-1", ZERO: VALID, UNIT: NA, BIG: str(2**62)}),
    ("design", "knots", {NAN: "nan", NEG: "-1", ZERO: VALID, UNIT: NA, BIG: str(10**12)}),
    ("fabrication", "n_levels", {NAN: "nan", NEG: "-16", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    ("reconstruction", "minutes", {NAN: "nan", NEG: "-1.0", ZERO: "0.0", UNIT: "3600.0", BIG: "1e12"}),
    ("reconstruction", "images", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    ("reconstruction", "size_px", {NAN: "nan", NEG: "-256", ZERO: "0", UNIT: NA, BIG: str(2**40)}),
    ("tolerance", "samples", {NAN: "nan", NEG: "-1", ZERO: VALID, UNIT: NA, BIG: str(10**12)}),
    ("tolerance", "supersample", {NAN: "nan", NEG: "-1", ZERO: "0", UNIT: NA, BIG: str(10**12)}),
    ("holder", "clearance_mm", {NAN: "nan", NEG: "-1.0", ZERO: "0.0", UNIT: "0.00025", BIG: "1e9"}),
]


def _wrong_unit(key) -> str:
    """A valid value of a length key written in another unit that leaves the range (else NA)."""
    from doefab.validate import LENGTH_UNITS

    if key.unit not in LENGTH_UNITS or not key.lo or key.lo <= 0:
        return NA
    mid = (key.lo * key.hi) ** 0.5  # valid in the key's unit
    for other, per in LENGTH_UNITS.items():
        v = mid * LENGTH_UNITS[key.unit] / per
        if other != key.unit and not key.lo <= v <= key.hi:
            return f"{v:.6g}"
    return NA


def _table_rows():
    """Every numeric key of the scene key table (``doefab.pipeline.scenekeys.KEYS``) not listed above."""
    from doefab.pipeline.scenekeys import KEYS

    listed = {(sec, name) for sec, name, _ in SCENE_KEYS}
    rows = []
    for k in KEYS:
        if k.kind not in ("float", "int") or k.lo is None or (k.section, k.name) in listed:
            continue
        f = k.kind == "float"
        rows.append((k.section, k.name, {NAN: "nan", NEG: "-1.0" if f else "-1",
                                         ZERO: VALID if k.lo <= 0 else ("0.0" if f else "0"),
                                         UNIT: _wrong_unit(k), BIG: "1e12" if f else str(10**12)}))
    return rows


SCENE_KEYS += _table_rows()
SCENE_KEYS += [("holder", name, kinds) for name, kinds in _holder_rows()  # a scene's [holder], as --set takes them
               if ("holder", name) not in {(sec, key) for sec, key, _ in SCENE_KEYS}]
SCENE_CASES = _expand(SCENE_KEYS, lambda row, value: (f"scene {row[0]}.{row[1]}", row[0], row[1], value))


def _scene_with(tmp: Path, section: str, key: str, value: str) -> Path:
    """scenes/hdr.toml with ``[section] key = value`` (and only the short holder stage, should a case get through)."""
    lines, out, current, done = (REPO / "scenes" / "hdr.toml").read_text().splitlines(), [], "", False
    for line in lines:
        if line.startswith("stages ="):
            line = 'stages = ["holder"]'
        if line.startswith("["):
            if current == section and not done:
                out.append(f"{key} = {value}")
                done = True
            current = line.strip("[]")
        if current == section and line.split("=")[0].strip() == key:
            continue
        out.append(line)
    if not done:
        out += ([] if current == section else [f"[{section}]"]) + [f"{key} = {value}"]
    path = tmp / "scene.toml"
    path.write_text("\n".join(out) + "\n")
    return path


@pytest.mark.parametrize("name, section, key, value", SCENE_CASES)
def test_scene_key(name, section, key, value, one_clear_error, no_work):
    one_clear_error(lambda f, t: ["run", _scene_with(t, section, key, value), "--out", t / "o"], 2, key)


# ---------------------------------------------------------------- command line: what else a scene check refuses
# (issue 37) every list key of the key table: not a list, empty, an item twice, an item below its range, a word it
# does not take; two keys that set one quantity; every key of the budget a scene names and every limit of its spec
# below and above its range and NaN, a whole-number key given a fraction; every key that takes a word, a switch or
# a text, and every key of a scene's [holder]: a value of the wrong type, one it does not take, an empty one.
# `run` and `doctor` both refuse each.

def _list_rows():
    from doefab.pipeline.scenekeys import KEYS

    rows = []
    for k in (k for k in KEYS if k.kind == "list"):
        name = f"{k.section}.{k.name}".lstrip(".")
        item = f'"{k.choices[0]}"' if k.item == "choice" else f"{(k.lo * k.hi) ** 0.5:.4g}"
        low = '"nonsense"' if k.item == "choice" else f"{k.lo / 10:g}"
        for kind, value, needle in (("not a list", item, "must be a list"), ("empty", "[]", "is empty"),
                                    ("twice", f"[{item}, {item}]", "holds {} more than once"),
                                    ("below range", f"[{low}]", "holds"), ("a word", '["far"]', "holds")):
            needle = needle.format(item.replace('"', "'"))
            rows.append((f"scene {name}-{kind}", k.section, k.name, value, f"{name} {needle}"))
    return rows


def _pair_rows():
    import itertools

    from doefab.pipeline.scene import SAME_QUANTITY

    return [(f"scene camera.{a}+{b}", "camera", a, f"1.0\n{b} = 1.0", f"camera.{b} = 1.0")
            for group, _ in SAME_QUANTITY for a, b in itertools.combinations(group, 2)]


def _budget_rows():
    from doefab.tolerance.errors import BUDGET_KEYS, WHOLE_KEYS
    from doefab.tolerance.spec import DELIVERED, limit_range, spec_keys

    ranges = [(sec, key, lo, hi) for sec, keys in BUDGET_KEYS.items() for key, (lo, hi) in
              ((k, r) for k, r in (keys or {}).items() if r)]
    ranges += [(f"spec.{task}", key, *limit_range(task, key)[:2]) for task in DELIVERED for key in spec_keys(task)]
    rows = [(f"budget {sec}.{key}-{kind}", sec, key, value) for sec, key, lo, hi in ranges
            for kind, value in (("below", f"{lo - 1:g}"), ("above", f"{hi * 10 + 1:g}"), (NAN, "nan"))]
    return rows + [(f"budget {sec}.{key}-fraction", sec, key, "16.7") for sec, key in sorted(WHOLE_KEYS)]


def _budget_scene(t: Path, table: str, key: str, value: str) -> Path:
    (t / "budget.toml").write_text(f"[{table}]\n{key} = {value}\n")
    return _scene_with(t, "tolerance", "budget", '"budget.toml"')


UNKNOWN, EMPTY, TYPE = "unknown", "empty", "wrong type"
SAID_AS = {"sensor.response": "response"}  # its checks say "sensor: camera response ..."


def _word_rows():
    """Every key of the key table that takes a word, a switch or a text: a value of the wrong type, a value it
    does not take (a word, a file that is not there, a level count no fab makes) and an empty one."""
    from doefab.pipeline.scenekeys import KEYS

    rows = []
    for k in (k for k in KEYS if k.kind in ("choice", "bool", "str")):
        name = f"{k.section}.{k.name}".lstrip(".")
        if k.kind == "bool":
            values = {TYPE: '"true"', UNKNOWN: "1"}
        elif k.choices and not isinstance(k.choices[0], str):  # numbers (fabrication.levels)
            values = {TYPE: f'"{k.choices[-2]}"', UNKNOWN: f"{k.choices[0] + 1}"}
        else:
            values = {TYPE: "1", UNKNOWN: '"nonsense"'}
        rows += [(f"scene {name}-{kind}", k.section, k.name, value, SAID_AS.get(name, name))
                 for kind, value in {**values, EMPTY: '""'}.items()]
    return rows


def _holder_word_rows():
    """A scene's [holder]: each length given as text, the mount a word it does not take or empty, a name that is
    no holder parameter."""
    from holder_cad.params import HolderParams

    rows = [(f"scene holder.{name}-{TYPE}", "holder", name, '"12"', name) for name in HolderParams().to_dict()
            if name != "mount"]
    rows += [(f"scene holder.mount-{kind}", "holder", "mount", value, "mount")
             for kind, value in ((UNKNOWN, '"screw"'), (EMPTY, '""'), (TYPE, "1"))]
    return rows + [("scene holder.unknown key", "holder", "thread_diameter", "49.0", "holder.thread_diameter")]


def _scene_check_cases():
    cases = [(name, lambda t, s=section, k=key, v=value: _scene_with(t, s, k, v), needle)
             for name, section, key, value, needle in _list_rows() + _pair_rows() + _word_rows() + _holder_word_rows()]
    cases += [(name, lambda t, s=sec, k=key, v=value: _budget_scene(t, s, k, v),
               f"tolerance.budget budget.toml: {sec}.{key}") for name, sec, key, value in _budget_rows()]
    return [pytest.param(cmd, make, needle, id=f"{cmd} {name}") for name, make, needle in cases
            for cmd in ("run", "doctor")]


@pytest.mark.parametrize("cmd, make, needle", _scene_check_cases())
def test_scene_check(cmd, make, needle, one_clear_error, no_work):
    one_clear_error(lambda f, t: [cmd, make(t)] + (["--out", t / "o"] if cmd == "run" else []), 2, needle)


# ---------------------------------------------------------------- command line: file and folder arguments

def _missing(t, name="nothing"):
    return t / name


def _empty_file(t, name="empty.x"):
    (t / name).write_bytes(b"")
    return t / name


def _corrupt_file(t, name="corrupt.x"):
    (t / name).write_bytes(b"\x00\xff\xfe garbage \x89PNG\r\n" * 20)
    return t / name


def _a_folder(t, name="folder.x"):
    (t / name).mkdir()
    (t / name / "something.txt").write_text("x")
    return t / name


def _empty_folder(t, name="emptydir"):
    (t / name).mkdir()
    return t / name


def _corrupt_copy(src, dst, damaged: str):
    """A copy of the folder ``src`` at ``dst`` with its file ``damaged`` overwritten by garbage."""
    shutil.copytree(src, dst)
    (dst / damaged).write_bytes(b"\x00\xff garbage")
    return dst


def _corrupt_design(f, t):
    return _corrupt_copy(f / "design", t / "design", "design.json")


def _corrupt_weights(t):
    w = t / "weights"
    w.mkdir()
    for task in ("hdr", "hyperspectral", "depth"):
        for v in ("proposed", "coded_only", "uncoded_only"):
            (w / f"{task}_{v}.pt").write_bytes(b"\x00garbage")
            (w / f"{task}_{v}.json").write_text("{not json")
    return w


def _corrupt_set(f, t):
    return _corrupt_copy(f / "maskset", t / "set", "manifest.json")


def _users_weights(t):
    """A folder of the user's holding a file named as training would name its weights."""
    w = t / "mine"
    w.mkdir()
    (w / "hdr_proposed.pt").write_bytes(b"the user's own network")
    return w


def _resume_folder(t, kind, content: bytes | None):
    """An earlier (marked) output of ``kind`` whose checkpoint is missing (None), empty or corrupt."""
    from doefab.io import mark_folder

    o = t / "o"
    o.mkdir()
    mark_folder(o, kind)
    if content is not None:
        (o / "checkpoint.pt").write_bytes(content)
    return o


SCENE_FILE = {"missing": (_missing, "not found"), "folder": (_a_folder, "is a folder"),
              "empty": (_empty_file, "holds no keys"), "corrupt": (_corrupt_file, "not UTF-8 text")}
DESIGN_DIR = {"missing": (lambda f, t: _missing(t), "design.json is missing"),
              "file": (lambda f, t: _corrupt_file(t), "is a file, not a design folder"),
              "empty": (lambda f, t: _empty_folder(t), "design.json is missing"),
              "corrupt": (_corrupt_design, "not valid JSON")}
DESIGN_COMMANDS = {"masks": ["masks", "--out", "{o}"], "train": ["train", "--task", "hyperspectral", "--out", "{o}"],
                   "evaluate": ["evaluate", "--task", "hyperspectral", "--weights-dir", "{o}w", "--out", "{o}"],
                   "finetune": ["finetune", "--out", "{o}"], "tolerance": ["tolerance", "--out", "{o}"],
                   "psf": ["psf", "--out", "{o}"]}


def _file_cases():
    cases = []
    for cmd in ("run", "doctor"):
        for kind, (make, needle) in SCENE_FILE.items():
            cases.append(pytest.param(lambda f, t, cmd=cmd, make=make: [cmd, make(t)] + (
                ["--out", t / "o"] if cmd == "run" else []), 2, needle, id=f"{cmd} SCENE-{kind}"))
    for kind, (make, needle) in SCENE_FILE.items():
        cases.append(pytest.param(lambda f, t, make=make: ["psf", "--scene", make(t), "--out", t / "o"], 2, needle,
                                  id=f"psf --scene-{kind}"))
    for cmd, rest in DESIGN_COMMANDS.items():
        for kind, (make, needle) in DESIGN_DIR.items():
            cases.append(pytest.param(lambda f, t, rest=rest, make=make: [
                *[str(t / "o") + a[3:] if a.startswith("{o}") else a for a in rest], "--design", make(f, t)],
                2, needle, id=f"{cmd} --design-{kind}"))
    height = {"missing": (_missing, "not found"), "folder": (_a_folder, "is a folder"),
              "empty": (_empty_file, "not a readable .npy"), "corrupt": (_corrupt_file, "not a readable .npy")}
    for kind, (make, needle) in height.items():
        cases.append(pytest.param(lambda f, t, make=make: ["psf", "--height", make(t), "--out", t / "o"], 2, needle,
                                  id=f"psf --height-{kind}"))
    verify = {"missing": (lambda f, t: _missing(t), 2, "not a folder"),
              "file": (lambda f, t: _corrupt_file(t), 2, "not a folder"),
              "empty": (lambda f, t: _empty_folder(t), 2, "manifest.json is missing"),
              "corrupt": (_corrupt_set, 3, "not valid JSON")}
    for kind, (make, status, needle) in verify.items():
        cases.append(pytest.param(lambda f, t, make=make: ["masks", "--verify", make(f, t)], status, needle,
                                  id=f"masks --verify-{kind}"))
    weights = {"missing": (_missing, "no weights"), "file": (_corrupt_file, "is a file"),
               "empty": (_empty_folder, "no weights"), "corrupt": (_corrupt_weights, "not valid JSON")}
    for kind, (make, needle) in weights.items():
        cases.append(pytest.param(lambda f, t, make=make: ["evaluate", "--task", "hdr", "--weights-dir", make(t),
                                                           "--out", t / "o"], 2, needle,
                                  id=f"evaluate --weights-dir-{kind}"))
        cases.append(pytest.param(lambda f, t, make=make: ["finetune", "--design", f / "design", "--weights-dir",
                                                           make(t), "--out", t / "o"], 2, "half-ring",
                                  id=f"finetune --weights-dir-{kind}"))
    response = {"missing": (_missing, "neither a known camera"), "folder": (_a_folder, "neither a known camera"),
                "empty": (_empty_file, "row(s)"), "corrupt": (_corrupt_file, "not a readable CSV")}
    for kind, (make, needle) in response.items():
        for cmd in (["train", "--task", "hyperspectral"], ["evaluate", "--task", "hyperspectral"]):
            cases.append(pytest.param(lambda f, t, make=make, cmd=cmd: [*cmd, "--sensor-response", make(t), "--out",
                                                                        t / "o"], 2, needle,
                                      id=f"{cmd[0]} --sensor-response-{kind}"))
    budget = {"missing": (_missing, "not found"), "folder": (_a_folder, "is a folder"),
              "corrupt": (_corrupt_file, "not UTF-8 text")}  # an empty budget: rows 4–6 of issue 21 (defaults)
    for kind, (make, needle) in budget.items():
        cases.append(pytest.param(lambda f, t, make=make: ["tolerance", "--design", f / "design", "--budget",
                                                           make(t), "--out", t / "o"], 2, needle,
                                  id=f"tolerance --budget-{kind}"))
    holder = {"missing": (_missing, "no holder.json"), "folder": (_a_folder, "no holder.json"),
              "empty": (_empty_file, "not a doefab holder.json"), "corrupt": (_corrupt_file, "not a doefab holder.json")}
    for kind, (make, needle) in holder.items():
        cases.append(pytest.param(lambda f, t, make=make: ["tolerance", "--design", f / "design", "--holder",
                                                           make(t), "--out", t / "o"], 2, needle,
                                  id=f"tolerance --holder-{kind}"))
    doctor_out = {"empty": (lambda t: "", "--out is empty"), "folder": (_a_folder, "is a folder"),
                  "a file of the user's": (_corrupt_file, "not an earlier doefab doctor report")}
    for kind, (make, needle) in doctor_out.items():
        cases.append(pytest.param(lambda f, t, make=make: ["doctor", REPO / "scenes" / "hdr.toml", "--out", make(t)],
                                  2, needle, id=f"doctor --out-{kind}"))
    for kind, make in (("file", _corrupt_file), ("a file of the user's inside", _users_weights)):
        cases.append(pytest.param(lambda f, t, make=make: ["train", "--task", "hdr", "--weights-dir", make(t),
                                                           "--out", t / "o"], 2,
                                  "is a file" if kind == "file" else "not written by doefab",
                                  id=f"train --weights-dir-{kind}"))
    resume = {"design": STREAK, "train": ["train", "--task", "hdr"]}
    for kind, content, needle in (("missing", None, "does not exist"), ("empty", b"", "corrupt"),
                                  ("corrupt", b"\x00garbage", "corrupt")):
        for cmd, args in resume.items():
            cases.append(pytest.param(lambda f, t, args=args, cmd=cmd, content=content: [
                *args, "--resume", "--out", _resume_folder(t, cmd, content)], 2, needle,
                id=f"{cmd} --resume checkpoint-{kind}"))
    return cases


@pytest.mark.parametrize("build, status, needle", _file_cases())
def test_file_argument(build, status, needle, one_clear_error, no_work):
    one_clear_error(build, status, needle)


# ---------------------------------------------------------------- command line: words, empty values, output folders
# (issue 37) every flag that takes a word, a list of words or a path: a word it does not take, a value of the wrong
# type, an empty value; every --out: empty, an existing file, a non-empty folder of the user's, a path under a file.

HALF_RING = REPO / "masks" / "half-ring" / "design"  # the committed depth design (finetune takes no other)


def _words(cmd, flag, unknown, wrong_type="1"):
    """A flag that takes one of a few words: one it does not take, a number, an empty value."""
    return [(cmd, flag, UNKNOWN, unknown, flag), (cmd, flag, TYPE, wrong_type, flag), (cmd, flag, EMPTY, "", flag)]


# (subcommand and the arguments it needs, flag, kind, value, what the line must hold); "--out OUT" is added
HDR_TRAIN, HDR_EVAL = ["train", "--task", "hdr"], ["evaluate", "--task", "hdr"]
TOLERANCE = ["tolerance", "--design", "{design}"]
DEVICE_COMMANDS = [STREAK, ["psf"], ["demo"], HDR_TRAIN, HDR_EVAL, ["finetune", "--design", HALF_RING], TOLERANCE,
                   ["run", REPO / "scenes" / "hdr.toml", "--quick"], ["doctor", REPO / "scenes" / "hdr.toml"]]
WORD_FLAGS = [
    *_words(["design"], "--task", "video"), *_words(STREAK, "--optimizer", "sgd"),
    *_words(STREAK, "--parameterization", "spline"), *_words(STREAK, "--start", "random"),
    *_words(["design", "--task", "half-ring"], "--ring-law", "linear"), *_words(STREAK, "--loss", "l2"),
    *_words(STREAK, "--n-levels", "3", wrong_type="16.0"),
    *_words(["psf"], "--preset", "canon"), *_words(["psf"], "--route", "raytrace"),
    *_words(["psf"], "--precision", "float16"),
    *_words(["masks", "--design", "{design}"], "--align-chain", "each"),
    *_words(["masks", "--design", "{design}"], "--resist", "neutral"),
    *_words(["masks", "--design", "{design}"], "--pattern-faces", "up"),
    *_words(["train"], "--task", "video"), *_words(HDR_TRAIN, "--variant", "best"),
    *_words(HDR_TRAIN, "--schedule", "step"), *_words(["evaluate"], "--task", "video"),
    *_words(HDR_EVAL, "--split", "train"), *_words(["scene", "new"], "--task", "video"),
    *_words(["run", REPO / "scenes" / "hdr.toml", "--quick"], "--force", "Design"),
    *_words(TOLERANCE, "--grid", "fine", wrong_type="2.5"), *_words(TOLERANCE, "--workers", "many", wrong_type="2.5"),
    (HDR_EVAL, "--variants", UNKNOWN, "proposed,best", "--variants"),
    (HDR_EVAL, "--variants", TYPE, "proposed;coded_only", "--variants"),
    (HDR_EVAL, "--variants", EMPTY, ",", "--variants"),
    (TOLERANCE, "--scheduler", UNKNOWN, "udp://127.0.0.1:8786", "--scheduler"),
    (TOLERANCE, "--scheduler", "no port", "tcp://127.0.0.1", "--scheduler"),
    (TOLERANCE, "--scheduler", EMPTY, "", "--scheduler"),
    (["masks", "--design", "{design}"], "--name", UNKNOWN, "../streak", "--name"),
    (["masks", "--design", "{design}"], "--name", EMPTY, "", "--name"),
    (["holder"], "--set", "no value", "thread_diameter_mm", "--set"), (["holder"], "--set", EMPTY, "", "--set"),
    (["holder"], "--set", "unknown name", "thread_diameter=49", "thread_diameter"),
    (["holder"], "--set", TYPE, "thread_diameter_mm=M49", "thread_diameter_mm"),
    (["holder"], "--set", "a fraction", "segments=64.5", "segments"),
    (["holder"], "--set", "mount " + UNKNOWN, "mount=screw", "mount"),
    (["holder"], "--set", "mount empty", "mount=", "mount"),
    # paths given empty
    (["masks"], "--design", EMPTY, "", "--design"), (["masks"], "--verify", EMPTY, "", "--verify"),
    (["finetune"], "--design", EMPTY, "", "--design is empty"),
    (["tolerance"], "--design", EMPTY, "", "--design is empty"),
    (TOLERANCE, "--budget", EMPTY, "", "--budget is empty"),
    (HDR_EVAL, "--weights-dir", EMPTY, "", "--weights-dir is empty"),
    (["train", "--task", "hyperspectral"], "--sensor-response", EMPTY, "", "--sensor-response is empty"),
    (["evaluate", "--task", "hyperspectral"], "--sensor-response", EMPTY, "", "--sensor-response is empty"),
    # --device on every command that computes: words that are no device, a GPU that is not there
    *[(cmd, "--device", kind, value, needle) for cmd in DEVICE_COMMANDS
      for kind, value, needle in ((UNKNOWN, "gpu", "'gpu' is not a device"), (TYPE, "cuda:x", "is not a device"),
                                  (EMPTY, "", "is not a device"), ("absent GPU", "cuda:4096", "CUDA device"))],
]
WORD_CASES = [pytest.param(cmd, flag, value, needle, id=f"{cmd[0]} {flag}-{kind}")
              for cmd, flag, kind, value, needle in WORD_FLAGS]


@pytest.mark.parametrize("cmd, flag, value, needle", WORD_CASES)
def test_word_flag(cmd, flag, value, needle, one_clear_error, no_work):
    one_clear_error(lambda f, t: _fill(cmd, f) + [flag, value, "--out", t / "o"], 2, needle)


OUT_COMMANDS = {"run": ["run", REPO / "scenes" / "hdr.toml", "--quick"], "demo": ["demo"], "psf": ["psf"],
                "design": STREAK, "masks": ["masks", "--design", "{design}"], "holder": ["holder"],
                "train": HDR_TRAIN, "finetune": ["finetune", "--design", HALF_RING], "tolerance": TOLERANCE}
OUT_KINDS = {EMPTY: lambda t: "", "a file": _corrupt_file, "a folder of the user's": _a_folder,
             "under a file": lambda t: _corrupt_file(t) / "o"}
SCENE_OUT = {EMPTY: lambda t: "", "not .toml": _corrupt_file, "an existing file": lambda t: _corrupt_file(t, "x.toml"),
             "in no folder": lambda t: t / "nothing" / "x.toml"}


def _out_cases():
    cases = [pytest.param(cmd, make, id=f"{name} --out-{kind}") for name, cmd in OUT_COMMANDS.items()
             for kind, make in OUT_KINDS.items()]
    return cases + [pytest.param(["scene", "new", "--task", "hdr"], make, id=f"scene new --out-{kind}")
                    for kind, make in SCENE_OUT.items()]


@pytest.mark.parametrize("cmd, make", _out_cases())
def test_out_flag(cmd, make, one_clear_error, no_work):
    one_clear_error(lambda f, t: _fill(cmd, f) + ["--out", make(t)], 2, "--out")


WEIGHTS = {"missing": (_missing, "no weights"), "file": (_corrupt_file, "is a file"),
           "empty folder": (_empty_folder, "no weights"), "corrupt": (_corrupt_weights, "not valid JSON")}
OUT = ("--out", lambda t: t / "o")


EARLY = [  # refused before any work (each was refused late, or not at all, before)
    # the weights a network-level study or an end-to-end fine-tune starts from (refused after making OUT and judging
    # the nominal part, and after 50 s of PSFs, before)
    *[(f"tolerance --networks --weights-dir-{kind}", [*TOLERANCE, "--networks", "--weights-dir", make, *OUT], needle)
      for kind, (make, needle) in WEIGHTS.items()],
    *[(f"finetune --weights-dir-{kind}", ["finetune", "--design", HALF_RING, "--weights-dir", make, *OUT], needle)
      for kind, (make, needle) in WEIGHTS.items()],
    ("finetune --weights-dir-another sensor's", ["finetune", "--design", HALF_RING, "--weights-dir",
                                                 REPO / "doefab" / "weights", "--read-noise-e", "20", *OUT],
     "another sensor"),
    ("finetune --weights-dir-empty", ["finetune", "--design", HALF_RING, "--weights-dir", "", *OUT], "--weights-dir"),
    ("tolerance --weights-dir-without --networks", [*TOLERANCE, "--weights-dir", _missing, *OUT], "--weights-dir"),
    ("train --design-empty", [*HDR_TRAIN, "--design", "", *OUT], "--design"),
    ("train --weights-dir-empty", [*HDR_TRAIN, "--weights-dir", "", *OUT], "--weights-dir"),
    ("psf --height-empty", ["psf", "--height", "", *OUT], "--height"),
    ("tolerance --holder-empty", [*TOLERANCE, "--holder", "", *OUT], "--holder"),
    *[(f"evaluate --out-{kind}", [*HDR_EVAL, "--out", make], "--out") for kind, make in OUT_KINDS.items()],
]


@pytest.mark.parametrize("args, needle", [pytest.param(args, needle, id=case) for case, args, needle in EARLY])
def test_refused_before_any_work(args, needle, one_clear_error, no_work):
    import doefab.reconstruction.loader

    no_work(doefab.reconstruction.loader, "psf_pair")  # a network's PSFs: evaluate's first work
    one_clear_error(lambda f, t: [a(t) if callable(a) else a for a in _fill(args, f)], 2, needle)


# ---------------------------------------------------------------- the public API

def _cam(**kw):
    base = dict(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                sensor_distance=20e-3, focus_distance=5.0)
    return doefab.Camera(**{**base, **kw})


def _levels():
    return np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)


def _height(v=None):
    h = doefab.levels_to_height(_levels(), _cam())
    return h if v is None else np.full_like(h, v)


def _fab(**kw):
    return doefab.fabricated_height(_levels(), _cam(), supersample=1, **kw)


def _psf(**kw):
    args = dict(wavelengths=[550e-9], depths=[5.0], kernel_size=15)
    args.update(kw)
    return doefab.split_aperture_psf(args.pop("height", None), _cam(), **args)


def _plan(**kw):
    args = dict(wavelengths=[550e-9], depths=[5.0], kernel_size=15)
    args.update(kw)
    return doefab.PSFPlan(_cam(), **args)


def _opt(**kw):
    return doefab.optimize("streak", **{"iterations": 2, "camera": _cam(), "progress": False,
                                        "task_params": {"kernel_size": 15, "arm_px": 4}, **kw})


def _pace(**kw):
    return doefab.design_time("streak", **{"iterations": 2, "camera": _cam(), "task_params": {"kernel_size": 15,
                                                                                             "arm_px": 4}, **kw})


def _field():
    import torch

    return torch.ones(32, 32, dtype=torch.complex64)


def _asm(**kw):
    return doefab.angular_spectrum(**{"field": _field(), "pitch": 5.4e-6, "wavelength": 550e-9, "distance": 1e-3,
                                      **kw})


def _gap(**kw):
    import torch

    return doefab.gap_transmittance(**{"height": torch.zeros(100, 100), "camera": _cam(), "wavelength": 550e-9,
                                       "depth": 5.0, "gap": 1e-3, **kw})


def _score(**kw):
    psf = np.zeros((3, 1, 15, 15))
    psf[:, :, 7, 7] = 0.5
    return doefab.depth_encoding_score(**{"psf": psf, "depths": [1.0, 2.0, 3.0], **kw})


def _captures(**kw):
    pair = _psf(wavelengths=[650e-9, 550e-9, 450e-9])
    return doefab.simulate_captures(**{"scene": np.full((3, 32, 32), 0.5), "pair": pair, **kw})


def _rec(value):
    rec = doefab.load_reconstructor("hdr")
    c = np.full((3, 64, 64), 0.5, np.float32)
    return rec(np.full((3, 64, 64), value, np.float64), c)


def _xtalk(fn, **kw):
    x = np.full((4, 4), 0.5)
    return fn(**{"alpha_lr": 0.05, "alpha_rl": 0.05, **kw}, **({"left": x, "right": x} if fn is doefab.mix_crosstalk
                                                               else {"left_star": x, "right_star": x}))


nan = float("nan")
# (API name, argument, call taking the value, {kind: value}); the error must name the argument
API = [
    ("Camera", "aperture_diameter", lambda v: _cam(aperture_diameter=v),
     {NAN: nan, NEG: -1e-3, ZERO: 0.0, UNIT: 8.64, BIG: 1e12}),
    ("Camera", "doe_pitch", lambda v: _cam(doe_pitch=v), {NAN: nan, NEG: -5.4e-6, ZERO: 0.0, UNIT: 10.8, BIG: 1e12}),
    ("Camera", "doe_pixels", lambda v: _cam(doe_pixels=v), {NAN: nan, NEG: -100, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("Camera", "sensor_pitch", lambda v: _cam(sensor_pitch=v), {NAN: nan, NEG: -5.4e-6, ZERO: 0.0, UNIT: 5.4, BIG: 1e12}),
    ("Camera", "sensor_distance", lambda v: _cam(sensor_distance=v),
     {NAN: nan, NEG: -0.02, ZERO: 0.0, UNIT: 20.0, BIG: 1e12}),
    ("Camera", "focus_distance", lambda v: _cam(focus_distance=v), {NAN: nan, NEG: -5.0, ZERO: 0.0, UNIT: NA, BIG: 1e12}),
    ("Camera", "design_wavelength", lambda v: _cam(design_wavelength=v),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("Material", "sellmeier_b", lambda v: doefab.Material("x", (v, 0.4, 0.9), (0.07, 0.12, 9.9)),
     {NAN: nan, NEG: -0.7, ZERO: VALID, UNIT: NA, BIG: 1e12}),
    ("Material", "sellmeier_c_um", lambda v: doefab.Material("x", (0.7, 0.4, 0.9), (v, 0.12, 9.9)),
     {NAN: nan, NEG: -0.07, ZERO: VALID, UNIT: 6.8e-8, BIG: 1e12}),
    ("blazed_grating_height", "period_pixels", lambda v: doefab.blazed_grating_height(_cam(), period_pixels=v),
     {NAN: nan, NEG: -16, ZERO: 0, UNIT: 86.4e-6, BIG: 1e12}),
    ("blazed_grating_height", "n_levels", lambda v: doefab.blazed_grating_height(_cam(), n_levels=v),
     {NAN: nan, NEG: -16, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("blazed_grating_height", "wavelength", lambda v: doefab.blazed_grating_height(_cam(), wavelength=v),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("split_aperture_psf", "height", lambda v: _psf(height=_height(v)), {NAN: nan, NEG: VALID, ZERO: VALID,
                                                                         UNIT: 500.0, BIG: 1e12}),
    ("split_aperture_psf", "wavelength", lambda v: _psf(wavelengths=[v]),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("split_aperture_psf", "depth", lambda v: _psf(depths=[v]), {NAN: nan, NEG: -5.0, ZERO: 0.0, UNIT: NA, BIG: 1e300}),
    ("split_aperture_psf", "kernel_size", lambda v: _psf(kernel_size=v),
     {NAN: nan, NEG: -15, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("split_aperture_psf", "pupil_oversample", lambda v: _psf(pupil_oversample=v),
     {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("split_aperture_psf", "center", lambda v: _psf(center=(v, 0.0)), {NAN: nan, NEG: VALID, ZERO: VALID,
                                                                       UNIT: 1e-3 * 1e3, BIG: 1e12}),
    ("PSFPlan", "wavelength", lambda v: _plan(wavelengths=[v]), {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0,
                                                                 BIG: 1e12}),
    ("PSFPlan", "kernel_size", lambda v: _plan(kernel_size=v), {NAN: nan, NEG: -15, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("PSFPlan", "lens_f_number", lambda v: doefab.PSFPlan(_cam(lens_f_number=v), [550e-9], [5.0], 15),
     {NAN: nan, NEG: -1.8, ZERO: 0.0, UNIT: NA, BIG: 60.0}),  # 60: a pupil narrower than the DOE's baffle
    ("angular_spectrum", "pitch", lambda v: _asm(pitch=v), {NAN: nan, NEG: -5.4e-6, ZERO: 0.0, UNIT: 5.4, BIG: 1e12}),
    ("angular_spectrum", "wavelength", lambda v: _asm(wavelength=v),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("angular_spectrum", "distance", lambda v: _asm(distance=v), {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: NA,
                                                                  BIG: 1e12}),
    ("angular_spectrum", "pad", lambda v: _asm(pad=v), {NAN: nan, NEG: -2, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("gap_transmittance", "wavelength", lambda v: _gap(wavelength=v),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("gap_transmittance", "depth", lambda v: _gap(depth=v), {NAN: nan, NEG: -5.0, ZERO: 0.0, UNIT: NA, BIG: VALID}),
    ("gap_transmittance", "gap", lambda v: _gap(gap=v), {NAN: nan, NEG: -1e-3, ZERO: VALID, UNIT: 1.6, BIG: 1e12}),
    ("gap_transmittance", "height", lambda v: _gap(height=__import__("torch").full((100, 100), v)),
     {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: 500.0, BIG: 1e12}),
    ("quantize_levels", "height", lambda v: doefab.quantize_levels(_height(v), _cam()),
     {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: 500.0, BIG: 1e12}),
    ("quantize_levels", "n_levels", lambda v: doefab.quantize_levels(_height(), _cam(), n_levels=v),
     {NAN: nan, NEG: -16, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("quantize_height", "height", lambda v: doefab.quantize_height(_height(v), _cam()),
     {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: 500.0, BIG: 1e12}),
    ("quantize_height", "n_levels", lambda v: doefab.quantize_height(_height(), _cam(), n_levels=v),
     {NAN: nan, NEG: -16, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("levels_to_height", "levels", lambda v: doefab.levels_to_height(np.full((4, 4), v), _cam()),
     {NAN: nan, NEG: -1, ZERO: VALID, UNIT: NA, BIG: 10**12}),
    ("levels_to_height", "n_levels", lambda v: doefab.levels_to_height(_levels(), _cam(), n_levels=v),
     {NAN: nan, NEG: -16, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("level_step", "n_levels", lambda v: doefab.level_step(_cam(), n_levels=v),
     {NAN: nan, NEG: -16, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("optimize", "iterations", lambda v: _opt(iterations=v), {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("optimize", "seed", lambda v: _opt(seed=v), {NAN: nan, NEG: -1, ZERO: VALID, UNIT: NA, BIG: 2**64}),
    ("optimize", "lr", lambda v: _opt(lr=v), {NAN: nan, NEG: -0.02, ZERO: 0.0, UNIT: NA, BIG: 1e12}),
    ("optimize", "sampling", lambda v: _opt(sampling=v), {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("optimize", "qat_fraction", lambda v: _opt(qat_fraction=v), {NAN: nan, NEG: -0.2, ZERO: VALID, UNIT: 20.0,
                                                                  BIG: 1e12}),
    ("optimize", "fab_weight", lambda v: _opt(fab_weight=v), {NAN: nan, NEG: -1.0, ZERO: VALID, UNIT: NA, BIG: 1e12}),
    ("optimize", "checkpoint_every", lambda v: _opt(checkpoint_every=v),
     {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: VALID}),
    ("optimize", "batch", lambda v: _opt(batch=v), {NAN: nan, NEG: -2, ZERO: VALID, UNIT: NA, BIG: 10**12}),
    ("optimize", "n_levels", lambda v: _opt(n_levels=v), {NAN: nan, NEG: -16, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("design_time", "steps", lambda v: _pace(steps=v), {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("design_time", "iterations", lambda v: _pace(iterations=v), {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("get_task", "kernel_size", lambda v: doefab.get_task("streak", kernel_size=v),
     {NAN: nan, NEG: -95, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("get_task", "period_m", lambda v: doefab.get_task("grating", period_m=v),
     {NAN: nan, NEG: -86.4e-6, ZERO: 0.0, UNIT: 86.4, BIG: 1e12}),
    ("mix_crosstalk", "alpha_lr", lambda v: _xtalk(doefab.mix_crosstalk, alpha_lr=v),
     {NAN: nan, NEG: -0.05, ZERO: VALID, UNIT: 5.0, BIG: 1e12}),
    ("unmix_crosstalk", "alpha_rl", lambda v: _xtalk(doefab.unmix_crosstalk, alpha_rl=v),
     {NAN: nan, NEG: -0.05, ZERO: VALID, UNIT: 5.0, BIG: 1e12}),
    ("unmix_crosstalk", "min_determinant", lambda v: _xtalk(doefab.unmix_crosstalk, min_determinant=v),
     {NAN: nan, NEG: -0.05, ZERO: 0.0, UNIT: 5.0, BIG: 1e12}),
    ("DualPixelCrosstalk", "alpha_lr", lambda v: doefab.DualPixelCrosstalk(v, 0.05),
     {NAN: nan, NEG: -0.05, ZERO: VALID, UNIT: 5.0, BIG: 1e12}),
    ("DualPixelCrosstalk.calibrated", "alpha_rl", lambda v: doefab.DualPixelCrosstalk.calibrated(0.05, v, rows=8),
     {NAN: nan, NEG: -0.05, ZERO: VALID, UNIT: 5.0, BIG: 1e12}),
    ("DualPixelCrosstalk.calibrated", "rows", lambda v: doefab.DualPixelCrosstalk.calibrated(0.05, 0.05, rows=v),
     {NAN: nan, NEG: -8, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("simulate_calibration", "level", lambda v: doefab.simulate_calibration(0.05, 0.05, rows=8, level=v),
     {NAN: nan, NEG: -0.5, ZERO: 0.0, UNIT: 50.0, BIG: 1e12}),
    ("simulate_calibration", "alpha_lr", lambda v: doefab.simulate_calibration(v, 0.05, rows=8),
     {NAN: nan, NEG: -0.05, ZERO: VALID, UNIT: 5.0, BIG: 1e12}),
    ("simulate_calibration", "seed", lambda v: doefab.simulate_calibration(0.05, 0.05, rows=8, rng=v),
     {NAN: nan, NEG: -1, ZERO: VALID, UNIT: NA, BIG: 2**80}),
    ("simulate_captures", "noise", lambda v: _captures(noise={"read": v}),
     {NAN: nan, NEG: -1.0, ZERO: 0.0, UNIT: NA, BIG: 1e12}),
    ("sensor_response", "wavelengths", lambda v: doefab.sensor_response([v]),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("Sensor", "full_well_e", lambda v: doefab.Sensor(full_well_e=v), {NAN: nan, NEG: -25000.0, ZERO: 0.0, UNIT: NA,
                                                                       BIG: 1e12}),
    ("Sensor", "read_noise_e", lambda v: doefab.Sensor(read_noise_e=v), {NAN: nan, NEG: -3.0, ZERO: VALID, UNIT: NA,
                                                                         BIG: 1e12}),
    ("simulate_captures", "scene", lambda v: _captures(scene=np.full((3, 32, 32), v)),
     {NAN: nan, NEG: -0.5, ZERO: VALID, UNIT: NA, BIG: VALID}),
    ("simulate_captures", "seed", lambda v: _captures(seed=v), {NAN: nan, NEG: -1, ZERO: VALID, UNIT: NA, BIG: 2**80}),
    ("simulate_captures", "depth_map", lambda v: _captures(depth_map=np.full((32, 32), v)),
     {NAN: nan, NEG: -2.0, ZERO: 0.0, UNIT: NA, BIG: VALID}),
    ("load_reconstructor(...)(coded, uncoded)", "coded", _rec, {NAN: nan, NEG: -0.5, ZERO: VALID, UNIT: 255.0,
                                                                  BIG: 1e12}),
    ("depth_encoding_score", "signal", lambda v: _score(signal=v), {NAN: nan, NEG: -0.25, ZERO: 0.0, UNIT: 25.0,
                                                                    BIG: 1e12}),
    ("depth_encoding_score", "contrast", lambda v: _score(contrast=v), {NAN: nan, NEG: -0.05, ZERO: 0.0, UNIT: 5.0,
                                                                        BIG: 1e12}),
    ("depth_encoding_score", "patch", lambda v: _score(patch=v), {NAN: nan, NEG: -8, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("depth_encoding_score", "full_well", lambda v: _score(full_well=v),
     {NAN: nan, NEG: -25000.0, ZERO: 0.0, UNIT: NA, BIG: 1e30}),
    ("depth_encoding_score", "read_noise", lambda v: _score(read_noise=v),
     {NAN: nan, NEG: -3.0, ZERO: VALID, UNIT: NA, BIG: 1e30}),
    ("depth_encoding_score", "depths", lambda v: _score(depths=[1.0, 2.0, v]),
     {NAN: nan, NEG: -3.0, ZERO: 0.0, UNIT: NA, BIG: VALID}),
    ("fabricated_height", "design_wavelength", lambda v: _fab(design_wavelength=v),
     {NAN: nan, NEG: -550e-9, ZERO: 0.0, UNIT: 550.0, BIG: 1e12}),
    ("fabricated_height", "depth_scale", lambda v: _fab(depth_scale=(v, 1, 1, 1)),
     {NAN: nan, NEG: -1.0, ZERO: 0.0, UNIT: 103.0, BIG: 1e12}),
    ("fabricated_height", "overlay", lambda v: _fab(overlay=((v, 0.0),) + ((0.0, 0.0),) * 3),
     {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: 0.5, BIG: 1e12}),
    ("fabricated_height", "rotation", lambda v: _fab(rotation=(v, 0, 0, 0)),
     {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: 5.0, BIG: 1e12}),
    ("fabricated_height", "edge_bias", lambda v: _fab(edge_bias=v), {NAN: nan, NEG: VALID, ZERO: VALID, UNIT: 0.1,
                                                                     BIG: 1e12}),
    ("fabricated_height", "roughness", lambda v: _fab(roughness=v), {NAN: nan, NEG: -1e-9, ZERO: VALID, UNIT: 20.0,
                                                                     BIG: 1e12}),
    ("fabricated_height", "corner_rounding", lambda v: _fab(corner_rounding=v),
     {NAN: nan, NEG: -1e-7, ZERO: VALID, UNIT: 0.2, BIG: 1e12}),
    ("fabricated_height", "roughness_corr", lambda v: _fab(roughness=1e-9, roughness_corr=v),
     {NAN: nan, NEG: -2e-6, ZERO: 0.0, UNIT: 2.0, BIG: 1e12}),
    ("fabricated_height", "supersample", lambda v: doefab.fabricated_height(_levels(), _cam(), supersample=v),
     {NAN: nan, NEG: -1, ZERO: 0, UNIT: NA, BIG: 10**12}),
    ("fabricated_height", "seed", lambda v: _fab(roughness=1e-9, seed=v), {NAN: nan, NEG: -1, ZERO: VALID, UNIT: NA,
                                                                            BIG: 2**80}),
]
API_CASES = _expand(API, lambda row, value: (f"{row[0]} {row[1]}", row[1], row[2], value))


@pytest.mark.parametrize("name, arg, call, value", API_CASES)
def test_api_argument(name, arg, call, value):
    with pytest.raises(DoefabError) as exc:
        call(value)
    msg = str(exc.value)
    assert arg.split("_")[0].rstrip("s") in msg, f"{name} = {value!r}: {msg!r} does not name {arg}"
    assert "\n" not in msg.strip()


# file and folder arguments of the API
API_FILES = [
    ("Design.load", lambda p: doefab.Design.load(p)),
    ("load_reconstructor weights_dir", lambda p: doefab.load_reconstructor("hdr", weights_dir=p)),
    ("Sensor response", lambda p: doefab.Sensor(response=str(p))),
    ("load_reconstructor design", lambda p: doefab.load_reconstructor("hdr", design=p)),
    ("finetune_end_to_end design_dir", lambda p: doefab.finetune_end_to_end(p, p.parent / "out", minutes=0.1)),
]


def _corrupt_folder(tmp: Path) -> Path:
    """A folder whose design record and weights are all garbage."""
    w = _corrupt_weights(tmp)
    (w / "design.json").write_bytes(b"\x00\xff garbage")
    (w / "levels.npy").write_bytes(b"\x00\xff garbage")
    return w


def _path(kind: str, tmp: Path) -> Path:
    return {"missing": lambda: _missing(tmp), "file": lambda: _corrupt_file(tmp),
            "empty": lambda: _empty_folder(tmp), "corrupt": lambda: _corrupt_folder(tmp)}[kind]()


@pytest.mark.parametrize("name, call", API_FILES, ids=[r[0] for r in API_FILES])
@pytest.mark.parametrize("kind", ["missing", "file", "empty", "corrupt"])
def test_api_path(name, call, kind, tmp_path):
    with pytest.raises(DoefabError):
        call(_path(kind, tmp_path))
    assert not (tmp_path / "out").exists()


# names of doefab.__all__ without numeric or file arguments, and why
NOTHING_TO_SWEEP = {
    "DoefabError": "exception type", "SamplingError": "exception type", "PRESETS": "constant", "TASKS": "constant",
    "FUSED_SILICA": "constant", "PSFPair": "result type (made by PSFPlan)", "__version__": "constant",
    "blank_height": "a camera only", "calibrate_crosstalk": "two captured image pairs (checked by the unmix cases)",
    "material_by_name": "a name (unknown names: tests/optics/test_materials.py)",
    "keep_freed_memory": "no arguments",
}


def test_the_sweep_covers_the_whole_public_api():
    swept = {row[0].split("(")[0] for row in API} | {r[0].split(" ")[0].split(".")[0] for r in API_FILES}
    assert set(doefab.__all__) <= swept | set(NOTHING_TO_SWEEP), set(doefab.__all__) - swept - set(NOTHING_TO_SWEEP)
    assert len(API_CASES) + len(FLAG_CASES) + len(HOLDER_CASES) + len(SCENE_CASES) >= 300


# ---------------------------------------------------------------- the sweep, one subcommand at a time

SUBCOMMANDS = ("demo", "design", "doctor", "evaluate", "finetune", "holder", "masks", "psf", "run", "scene",
               "tolerance", "train")
COMMAND_LINE = (test_numeric_flag, test_holder_parameter, test_scene_key, test_scene_check, test_file_argument,
                test_word_flag, test_out_flag, test_refused_before_any_work)


def _subcommand(case) -> str:
    return case.id.split(" ")[0]


def _only(test, cmd: str):
    """``test`` parametrized with the cases of subcommand ``cmd`` alone (None: it has none)."""
    (mark,) = [m for m in test.pytestmark if m.name == "parametrize"]
    mine = [c for c in mark.args[1] if _subcommand(c) == cmd]
    if not mine:
        return None

    @functools.wraps(test)
    def one(*args, **kwargs):
        return test(*args, **kwargs)

    one.pytestmark = []
    return pytest.mark.parametrize(mark.args[0], mine)(one)


def sweep(cmd: str) -> dict:
    """The command-line sweep's tests of subcommand ``cmd``, each parametrized with that subcommand's cases, and
    the work guard they use: a test module's globals (``globals().update(sweep("design"))``)."""
    assert cmd in SUBCOMMANDS, cmd
    tests = {t.__name__: _only(t, cmd) for t in COMMAND_LINE}
    return {"no_work": no_work, **{name: t for name, t in tests.items() if t is not None}}


def test_every_command_line_case_has_its_subcommands_file():
    """Every case of the sweep belongs to a subcommand that has a ``test_inputs_<subcommand>.py`` file: a case of
    a new subcommand is never left uncollected."""
    here = Path(__file__).parent
    seen = {_subcommand(c) for t in COMMAND_LINE for m in t.pytestmark if m.name == "parametrize" for c in m.args[1]}
    assert seen == set(SUBCOMMANDS)
    assert all((here / f"test_inputs_{cmd}.py").is_file() for cmd in SUBCOMMANDS)
