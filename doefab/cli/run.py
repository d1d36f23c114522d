"""``doefab run SCENE``: the main job — a scene file through design, masks, holder, reconstruction, tolerance
and a report (OUT/report.html and OUT/report.md), doing only what the scene needs.

Stages whose inputs did not change are kept from the previous run (so an interrupted run continues where it
stopped); --force STAGE recomputes one. --quick: smaller samples and images, same stages.
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
    from doefab.io import OutputDir, SIGNATURES
    from doefab.pipeline.run import run_scene
    from doefab.pipeline.scene import load_scene

    from doefab.pipeline.scene import STAGES

    bad = [f for f in args.force if f not in STAGES]
    if bad:
        raise DoefabError(f"--force {', '.join(bad)}: not a stage; stages are {', '.join(STAGES)}")
    scenes = [load_scene(s) for s in args.scene]  # every scene validated before any work
    if args.out and len(scenes) > 1:
        raise DoefabError("--out names one folder: give one scene, or leave --out out (out/run/<scene name>)")
    args.resume_hint = "finished stages are kept: rerun the same command to continue"
    outs = []
    for sc in scenes:
        out = Path(args.out) if args.out else Path("out/run") / sc.path.stem
        od = OutputDir(out, "run", replace=True, signatures=SIGNATURES.get("run", ()))
        outs.append(od)
    for sc, od in zip(scenes, outs):
        od.create()
        res = run_scene(sc, od.path, force=tuple(args.force), quick=args.quick)
        print(f"{sc.path}: {res['seconds']:.0f} s; report {od.path / 'report.html'}")
    return 0
