"""``run_scene``: the stages of a scene in order, each reused when its inputs are unchanged; then the report."""

from __future__ import annotations

import time
from pathlib import Path

from doefab.errors import DoefabError
from doefab.io import atomic_write_json
from doefab.pipeline.scene import STAGES, Scene
from doefab.pipeline.stages import resolve, run_stage

__all__ = ["run_scene"]


def run_scene(scene: Scene, out: str | Path, force: tuple = (), quick: bool = False, progress: bool = True) -> dict:
    out = Path(out)
    bad = [f for f in force if f not in STAGES]
    if bad:
        raise DoefabError(f"--force {bad}: stages are {list(STAGES)}")
    t0 = time.perf_counter()
    res = resolve(scene)  # validates the camera and the design settings before any work
    out.mkdir(parents=True, exist_ok=True)
    done: dict = {}
    for name in STAGES[:-1]:
        if name not in scene.stages:
            continue
        if name in ("masks", "reconstruction", "tolerance") and "design" not in done:
            raise DoefabError(f"stage {name} needs the design stage: add \"design\" to stages")
        if progress:
            print(f"[doefab run] {name} …", flush=True)
        done[name] = run_stage(scene, res, name, out, done, quick, force=name in force)
        if progress:
            info = done[name]
            took = ("kept from the previous run" if info.get("reused_from_previous_run")
                    else f"{info['seconds']:.1f} s")
            print(f"[doefab run] {name}: {info['status']} ({info.get('why', '')}) {took}", flush=True)
    report = None
    if "report" in scene.stages:
        from doefab.pipeline.report import write_report

        report = write_report(out, scene, done, res)
    summary = {"scene": str(scene.path), "task": scene.task, "quick": quick,
               "stages": {k: {kk: v.get(kk) for kk in ("status", "why", "seconds", "hash",
                                                        "reused_from_previous_run")} for k, v in done.items()},
               "seconds": round(time.perf_counter() - t0, 1), "report": report}
    atomic_write_json(out / "run.json", summary)
    return summary
