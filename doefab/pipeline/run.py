"""``run_scene``: the stages of a scene in order, each reused when its inputs are unchanged; then the report.

``prepare_scene`` does every check a scene run needs (the scene's settings against the committed design, and
that every stage folder the run would replace is doefab's) before any folder is created.
"""

from __future__ import annotations

import time
from pathlib import Path

from doefab._devices import describe_device, using_device
from doefab.errors import DoefabError
from doefab.io import MARKER, atomic_write_json, folder_lock, owned_by_doefab
from doefab.pipeline.resolved import ResolvedScene
from doefab.pipeline.scene import STAGES, Scene
from doefab.pipeline.stagerun import STAGE_FUNCS, STAGE_KIND, kept_note, run_stage
from doefab.pipeline.stages import resolve
from doefab.tolerance.schedulers import check_reachable

__all__ = ["run_scene", "prepare_scene", "foreign_stage_folders"]


def foreign_stage_folders(scene: Scene, out: str | Path) -> list[Path]:
    """The stage folders under ``out`` that this scene's run would replace but that are not doefab's (they lack
    the stage's ownership marker)."""
    out = Path(out)
    return [out / s for s in scene.stages if s in STAGE_FUNCS and not owned_by_doefab(out / s, STAGE_KIND, stage=s)]


def prepare_scene(scene: Scene, out: str | Path, force: tuple = ()) -> ResolvedScene:
    """Every check of a run of ``scene`` into ``out`` (no file is touched); returns ``resolve(scene)``."""
    bad = [f for f in force if f not in STAGES]
    if bad:
        raise DoefabError(f"--force {', '.join(bad)}: not a stage; stages are {', '.join(STAGES)}")
    res = resolve(scene)  # validates the camera and the design settings before any work
    if "tolerance" in scene.stages and scene.tolerance is not None:  # a Dask scheduler answers before any stage
        check_reachable(scene.tolerance.get("scheduler"), "tolerance.scheduler")
        _require_tolerance_memory(res, scene.tolerance)
    foreign = foreign_stage_folders(scene, out)
    if foreign:
        raise DoefabError(f"{', '.join(map(str, foreign))}: a stage folder without doefab's ownership marker "
                          f"({MARKER}) is never replaced: move it away or choose another --out")
    return res


def _require_tolerance_memory(res: ResolvedScene, tolerance: dict) -> None:
    """Refuse, before any stage, a tolerance stage whose parts judged at once do not fit in the memory available
    (the check ``doefab doctor`` shows: ``doctor.tolerance_memory_rows``)."""
    from doefab.pipeline.doctor import tolerance_memory_rows

    s = res.settings
    for row in tolerance_memory_rows(res.camera, s["n_levels"], len(s["wavelengths_m"]), tolerance):
        if not row["ok"]:
            raise DoefabError(f"{row['check']}: about {row['value'] / 1e9:.1f} GB needed, {row['limit'] / 1e9:.1f} GB "
                              f"available: use {row['fix']}")


def run_scene(scene: Scene, out: str | Path, force: tuple = (), quick: bool = False, progress: bool = True,
              res: ResolvedScene | None = None, device=None) -> dict:
    """Run ``scene`` into ``out`` (``res``: ``prepare_scene``'s result, computed here when not given) on ``device``
    (None: the scene's ``device`` key, else the default device)."""
    out = Path(out)
    t0 = time.perf_counter()
    with using_device(*((device, "device") if device is not None else (scene.device, "scene"))):  # checked first
        res = res if res is not None else prepare_scene(scene, out, force)
        out.mkdir(parents=True, exist_ok=True)
        with folder_lock(out, f"doefab run {scene.path}"):  # a second run on this folder is refused, not interleaved
            return _run_locked(scene, out, res, force, quick, progress, t0)


def _run_locked(scene: Scene, out: Path, res: ResolvedScene, force: tuple, quick: bool, progress: bool, t0: float) -> dict:
    if progress:
        for note in res.warnings:
            print(f"[doefab run] warning: {note}", flush=True)
    # the earlier run's summary (written at a run's end) goes now: an interrupted run leaves none to mislead
    from doefab.pipeline.report import REPORT_FILES

    for f in ("run.json", *(REPORT_FILES if "report" in scene.stages else ())):
        (out / f).unlink(missing_ok=True)
    done: dict = {}
    for name in STAGES[:-1]:
        if name not in scene.stages:
            continue
        if progress:
            print(f"[doefab run] {name} …", flush=True)
        done[name] = run_stage(scene, res, name, out, done, quick, force=name in force)
        if progress:
            info = done[name]
            took = kept_note(name, info) or f"{info['seconds']:.1f} s"
            print(f"[doefab run] {name}: {info['status']} ({info.get('why', '')}) {took}", flush=True)
    report = None
    if "report" in scene.stages:
        from doefab.pipeline.report import write_report

        report = write_report(out, scene, done, res, quick)
    summary = {"scene": str(scene.path), "task": scene.task, "quick": quick,
               "stages": {k: {kk: v.get(kk) for kk in ("status", "why", "seconds", "hash", "reused_from_previous_run",
                                                        "other_code")} for k, v in done.items()},
               "seconds": round(time.perf_counter() - t0, 1), "report": report, "warnings": res.warnings,
               "device": describe_device()}
    atomic_write_json(out / "run.json", summary)
    return summary
