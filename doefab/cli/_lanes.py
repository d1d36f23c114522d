"""The scenes of ``doefab run A B …``, each its own ``doefab run SCENE`` process: one at a time on this terminal
(``run_scene_process``), or up to ``jobs`` at a time in the order given, each one's output in a log of its own
(``run_lanes``).

The tolerance study through a task's network (most of a shipped scene's time) scores its scenes on one torch
thread, so a machine with more cores than one scene keeps busy can run scenes side by side. On 2 cores two at a
time gained little (the Monte Carlo already runs two worker processes; ``docs/results/main-job.md``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

__all__ = ["SCENE_BYTES", "jobs_arg", "scene_jobs", "scene_gpus", "lane_env", "run_lanes", "run_scene_process",
           "describe_status"]

#: the memory ``--jobs auto`` plans per scene: the shipped main job's peak, one scene at a time, a scene's process
#: and its tolerance workers together (10.8 GiB, ``docs/results/main-job.md``; two side by side peaked at 15.4 GiB)
SCENE_BYTES = 11 * 2**30
POLL_S = 0.2  # how often the running scenes are looked at


def jobs_arg(text: str):
    """``--jobs``: "auto" or a whole number ≥ 1 (argparse type). Example: ``jobs_arg("2") == 2``."""
    if text == "auto":
        return text
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"--jobs must be auto or a whole number of scenes ≥ 1, got {text!r}: e.g. "
                                         f"--jobs 2, or --jobs 1 to run the scenes one after another")
    return n


def scene_jobs(jobs, scenes: int, cores: int | None = None, available: int | None = None,
               gpus: int | None = None) -> int:
    """How many of ``scenes`` scenes run at once for ``jobs`` (``jobs_arg``'s "auto" or N): N, at most one per
    scene; "auto": one per core this process may use (``cores``; None: ``_devices.usable_cores``), no more than
    fit, ``SCENE_BYTES`` each, in the memory available (``available`` bytes; None: not known, not limiting), and
    no more than ``gpus`` where the scenes compute on GPUs (``scene_gpus``; None: not limiting), at least one.

    Example: ``scene_jobs("auto", 3, cores=2, available=64 * 2**30) == 2``."""
    from doefab._devices import usable_cores

    if jobs != "auto":
        return max(1, min(int(jobs), scenes))
    fit = scenes if available is None else available // SCENE_BYTES
    return max(1, min(scenes, cores or usable_cores(), fit, scenes if gpus is None else gpus))


def scene_gpus(devices: list[str], gpus: list[str]) -> tuple[int | None, list[str]]:
    """For scenes computing on ``devices`` (each the device in effect: the flag's, else the scene's, else the
    default) on a machine that sees ``gpus`` (``_devices.visible_gpus``): (how many GPUs "auto" may keep busy,
    None where no scene computes on one; the GPU each side-by-side lane is given, ``CUDA_VISIBLE_DEVICES``, in
    turn — none where a scene names its GPU, ``cuda:N``: the user placed it). Two scenes on one GPU would share
    its memory, so "auto" runs one scene per GPU, each on a GPU of its own.

    Example: ``scene_gpus(["auto", "cuda"], ["0", "1"]) == (2, ["0", "1"])``."""
    on_gpu = [d for d in devices if d.startswith("cuda") or (d == "auto" and gpus)]
    if not on_gpu or not gpus:
        return None, []
    return len(gpus), ([] if any(":" in d for d in on_gpu) else list(gpus))


def lane_env(jobs: int, cores: int | None = None, gpu: str | None = None, available: int | None = None) -> dict:
    """The environment of each scene's process when ``jobs`` run at once: this one's, with the cores shared out,
    ``cores // jobs`` each (at least one; ``cores`` None: ``_devices.usable_cores``) — the tolerance study's worker
    processes (``DOEFAB_CORES``) and torch's threads (``OMP_NUM_THREADS``, unless set to something already) —, the
    ``available`` bytes of memory too (``_memory.SHARE_ENV``, which the tolerance study's count of the parts that
    fit reads; None: not shared out), Python's output unbuffered, so each log is up to date (also when a scene is
    killed), and ``gpu`` the one GPU it sees (``CUDA_VISIBLE_DEVICES``; None: as this process).

    Example: ``lane_env(2, cores=2)["DOEFAB_CORES"] == "1"``."""
    from doefab._devices import CORES_ENV, usable_cores
    from doefab._memory import SHARE_ENV

    share = str(max(1, (cores or usable_cores()) // jobs))
    env = {**os.environ, CORES_ENV: share, "PYTHONUNBUFFERED": "1"}
    if available is not None:
        env[SHARE_ENV] = str(max(1, available // jobs))
    if not env.get("OMP_NUM_THREADS", "").strip():  # unset or empty
        env["OMP_NUM_THREADS"] = share
    if gpu is not None:
        env["CUDA_VISIBLE_DEVICES"] = gpu
    return env


def run_lanes(items, jobs: int, env=None) -> tuple[int, str | None]:
    """Run each ``(name, command, log)`` of ``items`` as a process of its own, up to ``jobs`` at a time in order,
    its output (stdout and stderr) to the file ``log``, in the environment ``env`` (None: this one's; a function:
    ``env(lane)`` for the lane 0..jobs-1 it starts in, the lowest free one); returns (exit status, what stopped
    them in words — e.g. "b failed (exit status 3)" — or None). Once one fails no other starts, and the running
    ones finish (their finished stages are kept either way). Ctrl-C (which the terminal sends to every scene too)
    or SIGTERM (passed on to each): the running ones are waited for while they clean up (a second Ctrl-C kills
    them), each one's end is shown as any other's, and the status is 130 or 143, the words naming a scene that had
    failed before. Any other error here stops the running ones (SIGTERM) before it is raised.

    Example: ``run_lanes([("a", [sys.executable, "-c", "pass"], Path("a.log"))], 2) == (0, None)``."""
    from doefab.cli._exits import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated

    pending, running, failed = list(items), {}, (0, None)
    try:
        while running or (pending and not failed[0]):
            while pending and not failed[0] and len(running) < jobs:
                lane = min(set(range(jobs)) - {v[3] for v in running.values()})
                _start(running, *pending.pop(0), env(lane) if callable(env) else env, lane)
            for child in _ended(running):  # every one that ended, before any other starts
                name, rc = _end(running, child)
                if rc and not failed[0]:
                    failed = (rc, f"{name} {describe_status(rc)}")
    except KeyboardInterrupt as exc:
        status = EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
        killed = _stop(running, status == EXIT_TERMINATED)
        for child in list(running):
            name, rc = _end(running, child)
            stopped = (0, EXIT_INTERRUPTED, EXIT_TERMINATED) + ((128 + 9,) if killed else ())  # 137: SIGKILL here
            if rc not in stopped and not failed[0]:  # it failed before the interrupt
                failed = (rc, f"{name} {describe_status(rc)}")
        what = describe_status(status).replace("was ", "were ", 1)
        return status, (f"the scenes {what}" + (f" after {failed[1]}" if failed[0] else "")
                        + ("; killed at the second interrupt" if killed else ""))
    except BaseException:
        _stop(running, True)
        raise
    return failed


def _start(running: dict, name: str, cmd: list[str], log: Path, env, lane: int) -> None:
    """Start ``cmd`` with its output to ``log`` and add it to ``running`` in ``lane``."""
    import subprocess

    log = Path(log)
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as out:
        child = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
    running[child] = (name, log, time.perf_counter(), lane)
    print(f"[doefab run] {name}: started; its output goes to {log}", flush=True)


def _end(running: dict, child) -> tuple[str, int]:
    """Take the ended ``child`` out of ``running`` and say how it ended; returns (its name, its exit status)."""
    name, log, start, _ = running.pop(child)
    rc = _status(child.returncode)
    _say_done(name, log, rc, time.perf_counter() - start)
    return name, rc


def _ended(running: dict) -> list:
    """The ``running`` processes that have ended, once at least one has (looked at every ``POLL_S`` seconds)."""
    while True:
        ended = [child for child in running if child.poll() is not None]
        if ended:
            return ended
        time.sleep(POLL_S)


def _say_done(name: str, log: Path, rc: int, seconds: float) -> None:
    tail = _last_lines(log, 1 if rc == 0 else 12)
    if rc == 0:
        print(f"[doefab run] {name}: done in {seconds:.0f} s" + (f" ({tail[-1]})" if tail else ""), flush=True)
        return
    print(f"[doefab run] {name} {describe_status(rc)} after {seconds:.0f} s; the end of {log}:", file=sys.stderr)
    for line in tail:
        print(f"    {line}", file=sys.stderr)


def _last_lines(log: Path, n: int) -> list[str]:
    """The last ``n`` non-empty lines of ``log``, each as a terminal shows it (a progress bar's last state)."""
    try:
        with open(log, newline="", errors="replace") as f:  # "\r" kept: it ends a progress bar's state
            text = f.read()
    except OSError:
        return []
    lines = [ln.split("\r")[-1].rstrip() for ln in text.split("\n")]
    return [ln for ln in lines if ln.strip()][-n:]


def _stop(running, terminate: bool) -> bool:
    """Wait for every ``running`` process after an interrupt, SIGTERM passed on to each first when ``terminate``;
    a second Ctrl-C kills those still running. Returns whether they were killed."""
    import signal

    if terminate:
        for child in running:
            child.send_signal(signal.SIGTERM)
    killed = False
    for child in running:
        while True:
            try:
                child.wait()
                break
            except KeyboardInterrupt:
                for c in running:
                    c.kill()
                killed = True
    return killed


def _status(returncode: int) -> int:
    """A process's exit status as a shell gives it: a death by signal N is 128 + N."""
    return 128 - returncode if returncode < 0 else returncode


def run_scene_process(cmd: list[str]) -> tuple[int, str]:
    """Start a scene's process and wait for it; returns (exit status, what happened in words). A death by signal
    N is status 128 + N. On Ctrl-C (which the terminal sends to the scene too) or SIGTERM (``Terminated``, passed
    on here) the scene is waited for while it cleans up, and the status is 130 or 143 whatever the scene
    returned; a second Ctrl-C kills it (a second SIGTERM is ignored: the clean-up is not cut short).

    Example: ``run_scene_process([sys.executable, "-c", "raise SystemExit(3)"]) == (3, "failed (exit status 3)")``."""
    import subprocess

    from doefab.cli._exits import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated

    child = None
    try:
        child = subprocess.Popen(cmd)
        rc = child.wait()
    except KeyboardInterrupt as exc:
        if child is None:
            raise
        status = EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
        killed = _stop([child], status == EXIT_TERMINATED)
        return status, describe_status(status) + ("; killed at the second interrupt" if killed else "")
    return _status(rc), describe_status(_status(rc))


def describe_status(rc: int) -> str:
    """A scene process's exit status in words. Example: ``describe_status(2) == "failed (exit status 2)"``."""
    import signal

    from doefab.cli._exits import EXIT_INTERRUPTED, EXIT_TERMINATED

    if rc in (EXIT_INTERRUPTED, EXIT_TERMINATED):
        return "was interrupted (Ctrl-C)" if rc == EXIT_INTERRUPTED else "was terminated (SIGTERM)"
    if rc > 128 and rc - 128 in {s.value for s in signal.Signals}:
        sig = signal.Signals(rc - 128)
        why = " (SIGKILL: often the system running out of memory; see dmesg)" if sig == signal.SIGKILL else ""
        return f"was killed by {sig.name}{why}"
    return f"failed (exit status {rc})"
