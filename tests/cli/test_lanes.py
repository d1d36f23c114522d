"""Several scenes at once (``doefab run A B --jobs N``): how many run side by side, their threads, their logs,
and what a failure or an interrupt does."""

import argparse
import sys

import pytest

from doefab.cli._lanes import SCENE_BYTES, jobs_arg, lane_env, run_lanes, scene_jobs


def test_jobs_is_auto_or_a_whole_number_of_scenes():
    assert jobs_arg("auto") == "auto" and jobs_arg("3") == 3
    for bad in ("0", "-1", "two", "1.5", ""):
        with pytest.raises(argparse.ArgumentTypeError, match="--jobs must be auto or a whole number"):
            jobs_arg(bad)


def test_auto_runs_one_scene_per_core_as_far_as_memory_allows():
    assert scene_jobs("auto", 3, cores=2, available=64 * 2**30) == 2  # the cores limit
    assert scene_jobs("auto", 3, cores=8, available=64 * 2**30) == 3  # the scenes limit
    assert scene_jobs("auto", 6, cores=8, available=4 * SCENE_BYTES + 1) == 4  # the memory limit
    assert scene_jobs("auto", 3, cores=8, available=SCENE_BYTES - 1) == 1  # never none
    assert scene_jobs("auto", 3, cores=4, available=None) == 3  # memory not known: not limiting
    assert scene_jobs(5, 3) == 3 and scene_jobs(1, 3) == 1  # a number: at most one per scene


def test_each_scene_gets_its_share_of_the_cores_unless_the_user_set_the_threads(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert lane_env(2, cores=2)["OMP_NUM_THREADS"] == "1"
    assert lane_env(2, cores=8)["OMP_NUM_THREADS"] == lane_env(2, cores=8)["DOEFAB_CORES"] == "4"
    assert lane_env(3, cores=2)["OMP_NUM_THREADS"] == "1" and lane_env(3, cores=2)["PYTHONUNBUFFERED"] == "1"
    monkeypatch.setenv("OMP_NUM_THREADS", "")  # set to nothing: torch's OpenMP would refuse it
    assert lane_env(2, cores=2)["OMP_NUM_THREADS"] == "1"
    monkeypatch.setenv("OMP_NUM_THREADS", "6")
    assert lane_env(2, cores=2)["OMP_NUM_THREADS"] == "6" and lane_env(2, cores=2)["DOEFAB_CORES"] == "1"


def test_a_scene_side_by_side_starts_as_many_tolerance_workers_as_its_share_of_the_cores(monkeypatch, tmp_path):
    """The environment reaches each scene, and the tolerance study's worker count (``montecarlo.auto_workers``)
    reads its share there: two scenes on fourteen cores each start seven workers, whatever this machine has."""
    code = ("from doefab.tolerance.montecarlo import auto_workers; import os; "
            "print(os.environ['OMP_NUM_THREADS'], auto_workers(1000))")
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    items = [(n, [sys.executable, "-c", code], tmp_path / f"{n}.log") for n in "ab"]
    assert run_lanes(items, 2, lane_env(2, cores=14)) == (0, None)
    assert (tmp_path / "a.log").read_text() == (tmp_path / "b.log").read_text() == "7 7\n"


def _meets(mine, other, timeout=60):
    """A process that writes ``mine``, then waits for ``other`` to exist (exit 0) or gives up (exit 5): two of
    them both succeed only when they run at the same time."""
    code = (f"import pathlib, sys, time; pathlib.Path({str(mine)!r}).write_text('x'); print('wrote', {mine.name!r}); "
            f"t = time.time()\nwhile not pathlib.Path({str(other)!r}).exists():\n    time.sleep(0.05)\n"
            f"    if time.time() - t > {timeout}: sys.exit(5)\nprint('met')")
    return [sys.executable, "-c", code]


def test_scenes_run_side_by_side_each_with_its_own_log(tmp_path, capsys):
    a, b = tmp_path / "a.flag", tmp_path / "b.flag"
    items = [("a.toml", _meets(a, b), tmp_path / "logs" / "a.log"),
             ("b.toml", _meets(b, a), tmp_path / "logs" / "b.log")]
    assert run_lanes(items, 2) == (0, None)
    assert (tmp_path / "logs" / "a.log").read_text() == "wrote a.flag\nmet\n"
    assert (tmp_path / "logs" / "b.log").read_text() == "wrote b.flag\nmet\n"
    out = capsys.readouterr().out
    assert "[doefab run] a.toml: started; its output goes to" in out and "[doefab run] b.toml: done in" in out
    assert "(met)" in out  # each scene's last line, as its own run prints its summary


def test_one_at_a_time_they_do_not_overlap(tmp_path):
    a, b = tmp_path / "a.flag", tmp_path / "b.flag"
    items = [("a", _meets(a, b, timeout=1), tmp_path / "a.log"),
             ("b", [sys.executable, "-c", "pass"], tmp_path / "b.log")]
    assert run_lanes(items, 1) == (5, "a")  # a waited in vain for b.flag, which no process writes
    assert not (tmp_path / "b.log").exists()  # and after a failure no other scene starts


def test_a_failure_stops_what_has_not_started_lets_the_running_finish_and_shows_the_logs_end(tmp_path, capsys):
    slow = [sys.executable, "-c", "import time; time.sleep(1); print('slow done')"]
    fail = [sys.executable, "-c", "import sys; print('progress\\rstage 3: bad input, fix it'); sys.exit(3)"]
    never = [sys.executable, "-c", "pass"]
    items = [("slow", slow, tmp_path / "slow.log"), ("bad", fail, tmp_path / "bad.log"),
             ("later", never, tmp_path / "later.log")]
    assert run_lanes(items, 2) == (3, "bad")
    assert (tmp_path / "slow.log").read_text() == "slow done\n" and not (tmp_path / "later.log").exists()
    err = capsys.readouterr().err
    assert "[doefab run] bad failed (exit status 3)" in err and "    stage 3: bad input, fix it" in err
    assert "progress" not in err  # a progress bar's earlier states are not shown


def test_scenes_that_end_together_are_all_seen_before_another_starts(tmp_path, monkeypatch):
    """A scene that fails in the same look as one that succeeds (the one that succeeded listed first) still
    keeps any further scene from starting."""
    from doefab.cli import _lanes

    monkeypatch.setattr(_lanes, "POLL_S", 3.0)  # both end within one look
    ok = [sys.executable, "-c", "pass"]
    bad = [sys.executable, "-c", "raise SystemExit(4)"]
    items = [("ok", ok, tmp_path / "ok.log"), ("bad", bad, tmp_path / "bad.log"), ("later", ok, tmp_path / "l.log")]
    assert run_lanes(items, 2) == (4, "bad")
    assert not (tmp_path / "l.log").exists()
