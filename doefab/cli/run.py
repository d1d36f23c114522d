"""``doefab run SCENE``: the main job — a scene file through design, masks, holder, reconstruction, tolerance
and a report (OUT/report.html and OUT/report.md), doing only what the scene needs.

Stages whose inputs did not change are kept from the previous run (so an interrupted run continues where it
stopped); --force STAGE recomputes one. --quick: smaller samples and images, same stages. Several scenes are all
checked first, then each runs in a process of its own (a scene's caches and its memory end with it).
"""

from __future__ import annotations

import argparse

from doefab.cli._args import add_device_arg


def register(sub) -> None:
    p = sub.add_parser("run", help="run a scene file end to end (the main job)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", nargs="+", help="scene TOML file(s), e.g. scenes/hdr.toml")
    p.add_argument("--out", default=None, help="output folder (default out/run/<scene name>; one per scene)")
    p.add_argument("--force", action="append", default=[], metavar="STAGE",
                   help="recompute this stage even if its inputs are unchanged (repeatable)")
    p.add_argument("--quick", action="store_true", help="smaller samples and images, same stages (CI)")
    add_device_arg(p, scene=True)
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from doefab._devices import check_device
    from doefab.errors import DoefabError
    from doefab.io import OutputDir
    from doefab.pipeline.run import prepare_scene, run_scene
    from doefab.pipeline.stagerun import has_progress
    from doefab.pipeline.scene import load_scene

    scenes = [load_scene(s) for s in args.scene]  # every scene validated before any work
    if args.out is not None and len(scenes) > 1:
        raise DoefabError("--out names one folder: give one scene, or leave --out out (out/run/<scene name>)")
    args.resume_hint = ("finished stages are kept: rerun the same command to continue" if not args.force else
                        "finished stages are kept: rerun the command without --force to continue (with it, the "
                        "forced stages start afresh again)")
    shared_output_folders(scenes)
    runs = []
    for sc in scenes:  # every check of every scene before the first folder is created
        if args.device is None and sc.device is not None:
            check_device(sc.device, "scene")  # a GPU the scene names that this machine lacks (--device overrides it)
        od = OutputDir(Path("out/run") / sc.path.stem if args.out is None else args.out, "run", replace=True)
        runs.append((sc, od, prepare_scene(sc, od.path, tuple(args.force))))
    if len(runs) > 1:
        del runs  # the checks' designs are not held while the scenes run
        return run_each_in_own_process(args)
    sc, od, res = runs[0]
    args.outdir = od  # a failure removes what this scene's run created, unless a stage finished
    args.keep_on_failure = lambda: has_progress(od.path, sc.stages)
    od.create()
    summary = run_scene(sc, od.path, force=tuple(args.force), quick=args.quick, res=res, device=args.device)
    report = (f"report {od.path / 'report.html'}" if summary["report"] else
              "no report written (\"report\" is not in the scene's stages)")
    print(f"{sc.path}: {summary['seconds']:.0f} s; {report}")
    return 0


def shared_output_folders(scenes) -> None:
    """Refuse scenes whose default output folders (out/run/<file name>) coincide: the later would replace the
    earlier's results."""
    from collections import defaultdict

    from doefab.errors import DoefabError

    by_folder = defaultdict(list)
    for sc in scenes:
        by_folder[sc.path.stem].append(str(sc.path))
    clash = {k: v for k, v in by_folder.items() if len(v) > 1}
    if clash:
        which = "; ".join(f"{', '.join(v)} would all write out/run/{k}" for k, v in clash.items())
        raise DoefabError(f"{which}: each scene needs an output folder of its own; rename a scene file, or run "
                          f"each alone with its own --out")


def run_each_in_own_process(args) -> int:
    """Run each of ``args.scene`` as its own ``doefab run SCENE`` process, in order, stopping at the first that
    fails (its exit status is returned; it printed its own error). Ctrl-C reaches the running scene from the
    terminal; SIGTERM is passed on to it; either way this process waits for the scene, and no later scene
    starts."""
    import sys

    flags = ([f for stage in args.force for f in ("--force", stage)] + (["--quick"] if args.quick else [])
             + (["--debug"] if getattr(args, "debug", False) else [])
             + (["--device", args.device] if args.device is not None else []))
    for scene in args.scene:
        rc, how = run_scene_process([sys.executable, "-m", "doefab", "run", scene, *flags])
        if rc != 0:
            print(f"[doefab run] stopped: {scene} {how}; the scenes after it were not run", file=sys.stderr)
            return rc
    return 0


def run_scene_process(cmd: list[str]) -> tuple[int, str]:
    """Start a scene's process and wait for it; returns (exit status, what happened in words). A death by signal
    N is status 128 + N. On Ctrl-C (which the terminal sends to the scene too) or SIGTERM (``Terminated``, passed
    on here) the scene is waited for while it cleans up, and the status is 130 or 143 whatever the scene
    returned; a second Ctrl-C kills it (a second SIGTERM is ignored: the clean-up is not cut short)."""
    import signal
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
        if status == EXIT_TERMINATED:
            child.send_signal(signal.SIGTERM)
        how = describe_status(status)
        while True:
            try:
                child.wait()
                break
            except KeyboardInterrupt:
                child.kill()
                how += "; killed at the second interrupt"
        return status, how
    rc = 128 - rc if rc < 0 else rc
    return rc, describe_status(rc)


def describe_status(rc: int) -> str:
    """A scene process's exit status in words."""
    import signal

    from doefab.cli._exits import EXIT_INTERRUPTED, EXIT_TERMINATED

    if rc in (EXIT_INTERRUPTED, EXIT_TERMINATED):
        return "was interrupted (Ctrl-C)" if rc == EXIT_INTERRUPTED else "was terminated (SIGTERM)"
    if rc > 128 and rc - 128 in {s.value for s in signal.Signals}:
        sig = signal.Signals(rc - 128)
        why = " (SIGKILL: often the system running out of memory; see dmesg)" if sig == signal.SIGKILL else ""
        return f"was killed by {sig.name}{why}"
    return f"failed (exit status {rc})"
