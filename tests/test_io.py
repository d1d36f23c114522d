"""Files and folders (``doefab.io``): staging folders of killed runs are removed, the umask is respected."""

import os
import stat

import pytest

from doefab.io import atomic_write_bytes, staging_dir


def test_stale_staging_folders_of_killed_runs_are_removed(tmp_path):
    dead = tmp_path / ".m.staging.999999999.abcd"  # no such process
    dead.mkdir()
    (dead / "big.gds").write_bytes(b"0" * 1000)
    live = tmp_path / f".m.staging.{os.getppid()}.efgh"  # a running process: left alone
    live.mkdir()
    with staging_dir(tmp_path / "m") as stage:
        (stage / "f").write_text("ok")
    assert not dead.exists() and live.exists()
    assert (tmp_path / "m" / "f").read_text() == "ok"


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_files_and_folders_respect_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        atomic_write_bytes(tmp_path / "a" / "f.bin", b"x")
        with staging_dir(tmp_path / "s") as stage:
            atomic_write_bytes(stage / "g.bin", b"y")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a" / "f.bin").stat().st_mode) == 0o666 & ~umask
    assert stat.S_IMODE((tmp_path / "s").stat().st_mode) == 0o777 & ~umask
    assert stat.S_IMODE((tmp_path / "s" / "g.bin").stat().st_mode) == 0o666 & ~umask


def test_json_ready_writes_non_finite_numbers_as_the_scene_files_do_and_keeps_the_rest():
    import json
    import math

    from doefab.io import json_ready

    got = json_ready({"a": [1.5, float("inf"), (float("-inf"), float("nan"))], "b": {"c": math.pi, "d": "x"},
                      "e": None, "f": 3})
    assert got == {"a": [1.5, "inf", ["-inf", "nan"]], "b": {"c": math.pi, "d": "x"}, "e": None, "f": 3}
    json.dumps(got, allow_nan=False)  # strict JSON


def _refuse(constant):
    raise ValueError(f"{constant}: not strict JSON")


def test_json_files_are_strict_and_read_back_with_their_non_finite_numbers(tmp_path):
    """``atomic_write_json`` writes what a strict parser (a browser's ``JSON.parse``, jq) reads; ``read_json`` gives
    back the same numbers, infinities and NaN included; other strings stay strings."""
    import json
    import math

    from doefab.io import atomic_write_json, read_json

    obj = {"margin": float("inf"), "low": float("-inf"), "rows": [1.25, float("nan")], "name": "x", "n": 3,
           "none": None, "nested": {"focus_distance_m": "inf"}}
    p = atomic_write_json(tmp_path / "r.json", obj)
    strict = json.loads(p.read_text(), parse_constant=_refuse)
    assert strict["margin"] == "inf" and strict["low"] == "-inf" and strict["rows"] == [1.25, "nan"]
    got = read_json(p)
    assert got["margin"] == math.inf and got["low"] == -math.inf and math.isnan(got["rows"][1])
    assert got["rows"][0] == 1.25 and got["name"] == "x" and got["n"] == 3 and got["none"] is None
    assert got["nested"]["focus_distance_m"] == math.inf  # a distance record's "inf" is the number it stands for


def test_a_cached_tolerance_step_is_reused_when_its_key_holds_infinities(tmp_path):
    """A resumed study reuses a step whose key holds an infinity (as a number or a distance record's "inf"): the
    key is compared as the file is read back."""
    from doefab.tolerance.report import cached_step

    key = {"depths_m": ["inf", 2.0], "limit": float("inf")}
    calls, reused = [], []
    for _ in range(2):
        cached_step(tmp_path, "tornado", key, lambda: calls.append(1) or [1.0, float("nan")], reused)
    assert len(calls) == 1 and reused == ["tornado"]


def test_a_cached_step_whose_key_holds_nan_is_reused_too(tmp_path):
    from doefab.tolerance.report import cached_step

    calls = []
    for _ in range(2):
        cached_step(tmp_path, "grid", {"bound": float("nan")}, lambda: calls.append(1) or 1.0)
    assert len(calls) == 1


def test_a_stage_folder_s_files_named_like_numbers_stay_file_names(tmp_path):
    """A user's files named "nan" and "inf" in a stage folder are recorded by name; the record read back
    (``read_json`` turns those strings into numbers) still names them, and a run keeps them."""
    from doefab.io import atomic_write_json, read_json
    from doefab.pipeline.stagerun import foreign_entries

    for name in ("nan", "inf", "design.json", "mine.txt"):
        (tmp_path / name).write_text("x")
    atomic_write_json(tmp_path / "stage.json", {"foreign": ["nan"], "files": ["design.json", "-inf"]})
    assert foreign_entries(tmp_path, read_json(tmp_path / "stage.json")) == {"nan", "inf", "mine.txt"}
