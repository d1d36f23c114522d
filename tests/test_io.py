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
