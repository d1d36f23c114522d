"""Several scenes at once (``doefab run A B --jobs N``): how many run side by side, their threads, their logs,
and what a failure or an interrupt does."""

import argparse
import sys

import pytest

from doefab.cli._lanes import SCENE_BYTES, jobs_arg, lane_env, run_lanes, scene_gpus, scene_jobs


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
    # a waited in vain for b.flag, which no process writes
    assert run_lanes(items, 1) == (5, "a failed (exit status 5)")
    assert not (tmp_path / "b.log").exists()  # and after a failure no other scene starts


def test_a_failure_stops_what_has_not_started_lets_the_running_finish_and_shows_the_logs_end(tmp_path, capsys):
    slow = [sys.executable, "-c", "import time; time.sleep(1); print('slow done')"]
    fail = [sys.executable, "-c", "import sys; print('progress\\rstage 3: bad input, fix it'); sys.exit(3)"]
    never = [sys.executable, "-c", "pass"]
    items = [("slow", slow, tmp_path / "slow.log"), ("bad", fail, tmp_path / "bad.log"),
             ("later", never, tmp_path / "later.log")]
    assert run_lanes(items, 2) == (3, "bad failed (exit status 3)")
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
    assert run_lanes(items, 2) == (4, "bad failed (exit status 4)")
    assert not (tmp_path / "l.log").exists()


def _cleans_up(flag, on="SIGINT", status=130):
    """A scene that says it started, then waits; on signal ``on`` it writes ``flag`` (its clean-up) and exits with
    ``status`` (as ``doefab run`` does on Ctrl-C or SIGTERM); on nothing it gives up after a minute (exit 5)."""
    code = (f"import pathlib, signal, sys, time\n"
            f"def stop(*_):\n    pathlib.Path({str(flag)!r}).write_text('x'); print('cleaned up'); sys.exit({status})\n"
            f"signal.signal(signal.{on}, stop); print('started', flush=True); time.sleep(60); sys.exit(5)")
    return [sys.executable, "-c", code]


def _interrupt_once_started(monkeypatch, logs, interrupt):
    """Patch the wait for scenes to end: once every log in ``logs`` says "started", call ``interrupt`` (which sends
    the signals and raises as the signal would) instead of waiting."""
    import time

    from doefab.cli import _lanes

    def look(running):
        while True:
            ended = [child for child in running if child.poll() is not None]
            if ended:
                return ended
            if all(log.exists() and "started" in log.read_text() for log in logs):
                interrupt(running)
            time.sleep(0.05)

    monkeypatch.setattr(_lanes, "_ended", look)


def test_ctrl_c_waits_for_the_scenes_to_clean_up_and_names_the_one_that_had_failed(tmp_path, monkeypatch, capsys):
    """Ctrl-C reaches every scene from the terminal (here: sent to each) while one had already failed: the running
    scene cleans up, its end is shown, no further scene starts, the status is 130 and the words keep the failure."""
    import signal

    from doefab.cli._exits import EXIT_INTERRUPTED

    flag, log = tmp_path / "cleaned", tmp_path / "long.log"
    bad = [sys.executable, "-c", "print('started'); raise SystemExit(3)"]
    items = [("long", _cleans_up(flag), log), ("bad", bad, tmp_path / "bad.log"),
             ("later", [sys.executable, "-c", "pass"], tmp_path / "later.log")]

    def ctrl_c(running):
        for child in running:
            child.send_signal(signal.SIGINT)
        raise KeyboardInterrupt

    _interrupt_once_started(monkeypatch, [log, tmp_path / "bad.log"], ctrl_c)
    rc, what = run_lanes(items, 2)
    assert rc == EXIT_INTERRUPTED and flag.exists() and not (tmp_path / "later.log").exists()
    assert what == "the scenes were interrupted (Ctrl-C) after bad failed (exit status 3)"
    err = capsys.readouterr().err
    assert "[doefab run] long was interrupted (Ctrl-C)" in err and "    cleaned up" in err


def test_a_scene_that_failed_just_before_the_interrupt_is_still_named(tmp_path, monkeypatch):
    """The interrupt comes while a scene has just failed, before its end was seen: its failure is kept in the words
    (the interrupted scene's own status, 130, is no failure)."""
    import signal

    from doefab.cli import _lanes
    from doefab.cli._exits import EXIT_INTERRUPTED

    flag, log = tmp_path / "cleaned", tmp_path / "long.log"
    bad = [sys.executable, "-c", "raise SystemExit(3)"]
    items = [("long", _cleans_up(flag), log), ("bad", bad, tmp_path / "bad.log")]

    def ctrl_c_once_bad_ended(running):
        import time

        while not (log.exists() and "started" in log.read_text()) or all(c.poll() is None for c in running):
            time.sleep(0.05)  # bad has ended, unseen; long runs
        for child in running:
            if child.poll() is None:
                child.send_signal(signal.SIGINT)
        raise KeyboardInterrupt

    monkeypatch.setattr(_lanes, "_ended", ctrl_c_once_bad_ended)
    assert run_lanes(items, 2) == (EXIT_INTERRUPTED, "the scenes were interrupted (Ctrl-C) after bad failed "
                                                     "(exit status 3)")
    assert flag.exists()


def test_sigterm_is_passed_on_to_each_scene_and_waited_for(tmp_path, monkeypatch, capsys):
    from doefab.cli._exits import EXIT_TERMINATED, Terminated

    flags = [tmp_path / "a.done", tmp_path / "b.done"]
    logs = [tmp_path / "a.log", tmp_path / "b.log"]
    items = [(n, _cleans_up(f, on="SIGTERM", status=143), log) for n, f, log in zip("ab", flags, logs)]

    def sigterm(running):  # only this process gets it: run_lanes must pass it on
        raise Terminated

    _interrupt_once_started(monkeypatch, logs, sigterm)
    assert run_lanes(items, 2) == (EXIT_TERMINATED, "the scenes were terminated (SIGTERM)")
    assert all(f.exists() for f in flags)
    err = capsys.readouterr().err
    assert "[doefab run] a was terminated (SIGTERM)" in err and "[doefab run] b was terminated (SIGTERM)" in err


def test_a_second_ctrl_c_kills_a_scene_still_cleaning_up(tmp_path):
    """A scene that ignores SIGTERM keeps ``_stop`` waiting; a Ctrl-C then (sent here to this process a moment
    later) kills it."""
    import os
    import signal
    import subprocess
    import threading

    from doefab.cli._lanes import _stop

    child = subprocess.Popen([sys.executable, "-c", "import signal, time; signal.signal(signal.SIGTERM, "
                              "signal.SIG_IGN); print('ready', flush=True); time.sleep(60)"], stdout=subprocess.PIPE)
    assert child.stdout.readline() == b"ready\n"
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C as Python has it by default (an
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))  # earlier test's worker set-up may not)
    timer.start()
    try:
        assert _stop([child], terminate=True) is True
    finally:
        timer.cancel()
        child.kill()
        signal.signal(signal.SIGINT, previous)
    assert child.wait() == -signal.SIGKILL


def test_on_gpus_auto_runs_one_scene_per_gpu_each_on_its_own():
    assert scene_gpus(["auto", "cuda"], ["4", "5"]) == (2, ["4", "5"])  # as CUDA_VISIBLE_DEVICES names them
    assert scene_gpus(["auto", "auto"], []) == (None, [])  # no GPU: auto is the CPU
    assert scene_gpus(["cpu", "cpu"], ["0"]) == (None, [])  # on the CPU: the GPUs limit nothing
    assert scene_gpus(["cuda:1", "auto"], ["0", "1"]) == (2, [])  # a scene placed on its GPU: not moved
    assert scene_jobs("auto", 3, cores=16, available=64 * SCENE_BYTES, gpus=1) == 1
    assert scene_jobs("auto", 3, cores=16, available=64 * SCENE_BYTES, gpus=2) == 2
    assert scene_jobs(3, 3, gpus=1) == 3  # a number is the user's
    assert lane_env(2, cores=2, gpu="5")["CUDA_VISIBLE_DEVICES"] == "5"


def test_each_scene_side_by_side_gets_its_share_of_the_memory(tmp_path, monkeypatch):
    """The memory available is shared out like the cores: each scene counts no more than its part as available
    (``_memory.available_bytes``, which the tolerance study's count of the parts that fit reads)."""
    from doefab._memory import SHARE_ENV

    assert lane_env(2, cores=2, available=8 * 2**30)[SHARE_ENV] == str(4 * 2**30)
    monkeypatch.delenv(SHARE_ENV, raising=False)
    assert SHARE_ENV not in lane_env(2, cores=2, available=None)  # not known: not shared out
    code = "from doefab._memory import available_bytes; print(available_bytes() == 2**30)"
    items = [("a", [sys.executable, "-c", code], tmp_path / "a.log")]
    assert run_lanes(items, 2, lane_env(2, cores=2, available=2 * 2**30)) == (0, None)
    assert (tmp_path / "a.log").read_text() == "True\n"


def test_a_scene_starts_in_the_lane_that_came_free_with_its_environment(tmp_path):
    """``env`` as a function of the lane: the second scene ends at once, so the third starts in its lane (its GPU),
    not in turn after the first, which still runs (it waits for the third)."""
    flag = tmp_path / "c.flag"
    show = "import os; print(os.environ['LANE_GPU'])"
    items = [("a", [sys.executable, "-c", show + "\n" + _meets(tmp_path / "a.flag", flag)[2]], tmp_path / "a.log"),
             ("b", [sys.executable, "-c", show], tmp_path / "b.log"),
             ("c", [sys.executable, "-c", show + f"; import pathlib; pathlib.Path({str(flag)!r}).write_text('x')"],
              tmp_path / "c.log")]
    assert run_lanes(items, 2, lambda lane: {**__import__("os").environ, "LANE_GPU": "gpu" + "01"[lane]}) == (0, None)
    assert [(tmp_path / f"{n}.log").read_text().split()[0] for n in "abc"] == ["gpu0", "gpu1", "gpu1"]
    assert (tmp_path / "a.log").read_text().split()[-1] == "met"


def test_side_by_side_on_gpus_each_scene_sees_one_gpu_of_its_own(monkeypatch):
    """``doefab run A B C`` on a machine with two GPUs (here told so): auto runs two scenes at a time, whatever
    its cores and memory, the lanes on GPU 3 and GPU 7 as ``CUDA_VISIBLE_DEVICES`` named them."""
    import doefab._devices as dv
    import doefab._memory as mem
    from doefab.cli import _lanes
    from doefab.cli.run import run_each_in_own_process

    seen = {}
    monkeypatch.setattr(dv, "visible_gpus", lambda: ["3", "7"])
    monkeypatch.setattr(dv, "usable_cores", lambda: 16)
    monkeypatch.setattr(mem, "available_bytes", lambda: 64 * SCENE_BYTES)
    monkeypatch.setattr(_lanes, "run_lanes", lambda items, jobs, env: seen.update(jobs=jobs, env=env) or (0, None))
    args = argparse.Namespace(scene=["a.toml", "b.toml", "c.toml"], force=[], quick=True, device=None, jobs="auto")
    assert run_each_in_own_process(args, ["auto", "cuda", "auto"]) == 0
    assert seen["jobs"] == 2 and [seen["env"](lane)["CUDA_VISIBLE_DEVICES"] for lane in (0, 1)] == ["3", "7"]
    assert run_each_in_own_process(args, ["cpu", "cpu", "cpu"]) == 0
    assert seen["jobs"] == 3 and isinstance(seen["env"], dict)  # on the CPU: one per core, no GPU given
