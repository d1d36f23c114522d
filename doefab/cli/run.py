"""``doefab run SCENE``: the main job — a scene file through design, masks, holder, reconstruction, tolerance
and a report (OUT/report.html and OUT/report.md), doing only what the scene needs.

Stages whose inputs did not change are kept from the previous run (so an interrupted run continues where it
stopped); --force STAGE recomputes one. --quick: smaller samples and images, same stages. Several scenes are all
checked first, then each runs in a process of its own (a scene's caches and its memory end with it), --jobs of
them at a time (default: one per core, as memory allows), in the order given: list the longest first.
"""

from __future__ import annotations

import argparse

from doefab.cli._args import add_device_arg
from doefab.cli._lanes import jobs_arg, run_scene_process


def register(sub) -> None:
    p = sub.add_parser("run", help="run a scene file end to end (the main job)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", nargs="+", help="scene TOML file(s), e.g. scenes/hdr.toml")
    p.add_argument("--out", default=None, help="output folder (default out/run/<scene name>; one per scene)")
    p.add_argument("--force", action="append", default=[], metavar="STAGE",
                   help="recompute this stage even if its inputs are unchanged (repeatable)")
    p.add_argument("--quick", action="store_true", help="smaller samples and images, same stages (CI)")
    p.add_argument("--jobs", type=jobs_arg, default="auto", metavar="N",
                   help="with several scenes, how many run at once, each its own process with its output in "
                        "out/run/<scene name>.log: a number, or auto (default: one per core, as many as fit in "
                        "the memory available at 11 GiB each, one per GPU on GPUs); 1 runs them one after another "
                        "on this terminal")
    add_device_arg(p, scene=True)
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from doefab._devices import check_device, default_device
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
        return run_each_in_own_process(args, [args.device or sc.device or default_device() for sc in scenes])
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


def run_each_in_own_process(args, devices: list[str]) -> int:
    """Run each of ``args.scene`` as its own ``doefab run SCENE`` process, ``args.jobs`` at a time
    (``_lanes.scene_jobs``; ``devices``: each scene's device in effect — side by side on GPUs, each scene is given
    one of its own, ``_lanes.scene_gpus``) in order; one at a time each prints to this terminal, several at once
    each to out/run/<scene name>.log. Stops starting scenes at the first that fails (its exit status is returned; it
    printed its own error). Ctrl-C reaches the running scenes from the terminal; SIGTERM is passed on to them;
    either way this process waits for them, and no later scene starts."""
    import sys
    from pathlib import Path

    from doefab._devices import device_syntax, visible_gpus
    from doefab._memory import available_bytes
    from doefab.cli._lanes import lane_env, run_lanes, scene_gpus, scene_jobs

    devices = [device_syntax(d) for d in devices]
    gpus, pins = scene_gpus(devices, visible_gpus() if any(d != "cpu" for d in devices) else [])
    flags = ([f for stage in args.force for f in ("--force", stage)] + (["--quick"] if args.quick else [])
             + (["--debug"] if getattr(args, "debug", False) else [])
             + (["--device", args.device] if args.device is not None else []))
    commands = [[sys.executable, "-m", "doefab", "run", scene, *flags] for scene in args.scene]
    available = available_bytes()
    jobs = scene_jobs(getattr(args, "jobs", 1), len(commands), available=available, gpus=gpus)
    if jobs > 1:
        env = lane_env(jobs, available=available)
        on = f", each on GPU {' or '.join(pins[:jobs])} (CUDA_VISIBLE_DEVICES)" if pins else ""
        print(f"[doefab run] {len(commands)} scenes, {jobs} at a time (torch on {env['OMP_NUM_THREADS']} thread(s) "
              f"each{on}; --jobs 1 runs them one after another)", flush=True)
        lanes = (lambda lane: lane_env(jobs, gpu=pins[lane % len(pins)], available=available)) if pins else env
        rc, what = run_lanes([(s, c, Path("out/run") / f"{Path(s).stem}.log") for s, c in zip(args.scene, commands)],
                             jobs, lanes)
    else:
        rc, what = 0, None
        for s, cmd in zip(args.scene, commands):
            rc, how = run_scene_process(cmd)
            if rc:
                what = f"{s} {how}"
                break
    if rc:
        print(f"[doefab run] stopped: {what}; the scenes not yet started were not run", file=sys.stderr)
    return rc
