"""``doefab run SCENE``: the main job — a scene file through design, masks, holder, reconstruction, tolerance
and a report (OUT/report.html and OUT/report.md), doing only what the scene needs.

Stages whose inputs did not change are kept from the previous run (so an interrupted run continues where it
stopped); --force STAGE recomputes one. --quick: smaller samples and images, same stages. Several scenes are all
checked first, then each runs in a process of its own (a scene's caches and its memory end with it).
"""

from __future__ import annotations

import argparse


def register(sub) -> None:
    p = sub.add_parser("run", help="run a scene file end to end (the main job)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", nargs="+", help="scene TOML file(s), e.g. scenes/hdr.toml")
    p.add_argument("--out", default=None, help="output folder (default out/run/<scene name>; one per scene)")
    p.add_argument("--force", action="append", default=[], metavar="STAGE",
                   help="recompute this stage even if its inputs are unchanged (repeatable)")
    p.add_argument("--quick", action="store_true", help="smaller samples and images, same stages (CI)")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from doefab.errors import DoefabError
    from doefab.io import OutputDir
    from doefab.pipeline.run import prepare_scene, run_scene
    from doefab.pipeline.stages import has_progress
    from doefab.pipeline.scene import load_scene

    scenes = [load_scene(s) for s in args.scene]  # every scene validated before any work
    if args.out is not None and len(scenes) > 1:
        raise DoefabError("--out names one folder: give one scene, or leave --out out (out/run/<scene name>)")
    args.resume_hint = "finished stages are kept: rerun the same command to continue"
    runs = []
    for sc in scenes:  # every check of every scene before the first folder is created
        od = OutputDir(Path("out/run") / sc.path.stem if args.out is None else args.out, "run", replace=True)
        runs.append((sc, od, prepare_scene(sc, od.path, tuple(args.force))))
    if len(runs) > 1:
        return run_each_in_own_process(args)
    sc, od, res = runs[0]
    args.outdir = od  # a failure removes what this scene's run created, unless a stage finished
    args.keep_on_failure = lambda: has_progress(od.path, sc.stages)
    od.create()
    summary = run_scene(sc, od.path, force=tuple(args.force), quick=args.quick, res=res)
    report = (f"report {od.path / 'report.html'}" if summary["report"] else
              "no report written (\"report\" is not in the scene's stages)")
    print(f"{sc.path}: {summary['seconds']:.0f} s; {report}")
    return 0


def run_each_in_own_process(args) -> int:
    """Run each of ``args.scene`` as its own ``doefab run SCENE`` process, in order, stopping at the first that
    fails (its exit code is returned; it printed its own error)."""
    import subprocess
    import sys

    flags = [f for stage in args.force for f in ("--force", stage)] + (["--quick"] if args.quick else [])
    for scene in args.scene:
        rc = subprocess.run([sys.executable, "-m", "doefab", "run", scene, *flags]).returncode
        if rc != 0:
            print(f"[doefab run] stopped: {scene} failed (exit {rc}); the scenes after it were not run",
                  file=sys.stderr)
            return rc
    return 0
