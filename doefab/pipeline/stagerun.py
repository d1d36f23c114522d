"""Running one stage of ``doefab run``: its inputs' hash, reuse of a finished stage with the same inputs, what
an interrupted one keeps, and its folder's bookkeeping (``stage.json``, the ownership marker, the user's files
left in place). The stages themselves are ``doefab.pipeline.stages``.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from pathlib import Path

from doefab.applications import has
from doefab.errors import DoefabError
from doefab.io import MARKER, atomic_write_json, mark_folder, owned_by_doefab, read_json
from doefab.pipeline.resolved import ResolvedScene
from doefab.pipeline.scenekeys import HOW_NOT_WHAT
from doefab.pipeline.sceneholder import scene_die
from doefab.pipeline.stages import (_scene_budget, networks_trained_here, stage_design, stage_holder, stage_masks,
                                    stage_reconstruction, stage_tolerance)
from doefab.pipeline.sceneholder import scene_holder
from doefab.pipeline.system import resolve, scene_sensor

__all__ = ["STAGE_FUNCS", "STAGE_KIND", "run_stage", "stage_hash", "has_progress", "budget_digest", "code_sha256",
           "kept_note"]

STAGE_KIND = "run stage"  # the ownership marker's kind of a stage folder (its ``stage`` field names the stage)


@functools.lru_cache(maxsize=1)
def code_sha256() -> str:
    """The digest of this doefab's sources (``io.sources_sha256``), recorded in each finished stage's
    ``stage.json``: a stage kept from a run of other code is reused as it is (its inputs' hash leaves the code out,
    so that an upgrade does not recompute hours of work unasked) and ``kept_note`` says so."""
    from doefab.io import sources_sha256

    return sources_sha256(Path(__file__).resolve().parents[2], ("doefab",))[:16]


def kept_note(name: str, info: dict) -> str:
    """What the run log and the report say of stage ``name`` whose record ``info`` ``run_stage`` returned: empty
    when it ran, else that it was kept, and, when other doefab code (or code that did not record itself) made it,
    which flag computes it again."""
    if not info.get("reused_from_previous_run"):
        return ""
    if not info.get("other_code"):
        return "kept from the previous run"
    return f"kept from the previous run, made by other doefab code: --force {name} computes it again"


def _h(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


#: what a stage keeps from an interrupted run of the same inputs: the design's optimiser checkpoint, the networks'
#: training runs and finished weights, the tolerance study's finished Monte Carlo parts and steps (each checks
#: that it belongs to its run); PROGRESS: the files among them that are work worth keeping after a failure
RESUMABLE = {"design": ("checkpoint.pt", "history.csv"),
             "reconstruction": ("run_proposed", "run_coded_only", "run_uncoded_only", "weights"),
             "tolerance": ("samples.jsonl", "steps")}
PROGRESS = {"design": ("checkpoint.pt",), "reconstruction": ("run_*/checkpoint.pt", "weights/*.pt"),
            "tolerance": ("samples.jsonl", "steps/*.json", "steps/*.parts.jsonl")}


def has_progress(folder: Path, stages) -> bool:
    """Whether a run folder holds work worth keeping after a failure: a finished stage, or a stage's saved
    checkpoint, parts or steps (``PROGRESS``)."""
    for s in stages:
        try:
            if read_json(Path(folder) / s / "stage.json").get("complete"):
                return True
        except (OSError, ValueError):
            pass
        if any(next((Path(folder) / s).glob(g), None) is not None for g in PROGRESS.get(s, ())):
            return True
    return False


STAGE_FUNCS = {"design": stage_design, "masks": stage_masks, "holder": stage_holder,
               "reconstruction": stage_reconstruction, "tolerance": stage_tolerance}
UPSTREAM = {"design": (), "masks": ("design",), "holder": (), "reconstruction": ("design",),
            "tolerance": ("design", "masks", "holder", "reconstruction"),
            "report": ("design", "masks", "holder", "reconstruction", "tolerance")}
SECTION = {"masks": ("fabrication",), "holder": ("holder",),  # the design's: ResolvedScene.design_key
           "reconstruction": ("reconstruction",), "tolerance": ("tolerance",), "report": ()}


def stage_hash(scene, name: str, done: dict, quick: bool, res: ResolvedScene | None = None,
               root: Path | None = None) -> str:
    """The stage's inputs: for the design the resolved scene's ``design_key`` (its design settings, however the
    scene file spelled them; ``res``: the scene resolved, resolved here when None and needed), for the others
    their scene sections (the masks also their die's side, which the holder's keys set); the task, --quick, its
    upstream stages' hashes, for the holder the source of ``holder_cad`` that builds it and, for the stages that
    draw fabricated parts from it, the tolerance budget's content (not only its file name); for the tolerance
    stage the scene size its network judge reads (``reconstruction.size_px``, where not the default 256; --quick
    sets its own) and, in the run in ``root``, the
    networks it judges through (``networks_trained_here``: those its
    reconstruction stage trained, also when this run did not run that stage)."""
    if name in ("design", "masks", "holder") and res is None:
        res = resolve(scene)
    if name == "design":
        parts = {"design": res.design_key()}
    else:
        parts = {s: _what(s, scene.raw.get(s)) for s in SECTION[name]}
    if name == "masks":  # the die the masks are laid out on (its side and its key) follows the holder's keys too
        parts["die_m"] = res.die_m
        parts["die_chamfer_m"], parts["substrate_thickness_m"] = scene_die(scene)
    parts["task"] = scene.task
    parts["quick"] = quick
    parts["upstream"] = {u: done.get(u, {}).get("hash") for u in UPSTREAM[name]}
    if name == "holder":  # the DOE's die and aperture, and holder_cad's code: another version builds another part
        import holder_cad

        from doefab.io import sources_sha256

        parts["holder"] = scene_holder(scene, res.camera)
        parts["code"] = sources_sha256(Path(holder_cad.__file__).resolve().parent.parent, ("holder_cad",))
    if name in ("reconstruction", "tolerance"):
        parts["budget"] = budget_digest(scene)
        if scene.raw.get("sensor"):  # by content (a CSV's curves), and only when it is not the default sensor
            parts.update(scene_sensor(scene).entry(has(scene.task, "spectral")))
    size = int((scene.raw.get("reconstruction") or {}).get("size_px", 256))
    if name == "tolerance" and size != 256 and not quick:  # the scene size a network judge reads each part at
        parts["judge_size_px"] = size  # (only when not the default: earlier runs' hashes stand)
    if name == "tolerance" and root is not None:
        own, _ = networks_trained_here(scene, res if res is not None else resolve(scene), Path(root))
        if own is not None:  # (none: the hash is as without ``root``)
            parts["networks"] = read_json(own.parent / "stage.json").get("hash")
    return _h(parts)


def _what(section: str, values):
    """A scene section's keys less those that say how a stage runs, not what it computes (``HOW_NOT_WHAT``)."""
    how = HOW_NOT_WHAT.get(section, ())
    return {k: v for k, v in values.items() if k not in how} if isinstance(values, dict) and how else values


def budget_digest(scene) -> str | None:
    """A digest of the scene's tolerance budget as loaded (None without a [tolerance] section)."""
    b = _scene_budget(scene)
    return None if b is None else _h({k: v for k, v in b.items() if k != "defaults_used"})


def run_stage(scene, res, name: str, out_root: Path, done: dict, quick: bool, force: bool) -> dict:
    """Run (or reuse) one stage; its record (status, why, seconds, hash) is kept in ``<stage>/stage.json``."""
    out = out_root / name
    h = stage_hash(scene, name, done, quick, res, out_root)
    rec_path = out / "stage.json"
    old = {}
    if rec_path.is_file():
        try:
            old = read_json(rec_path)
        except ValueError:
            old = {}
    if not force and old.get("hash") == h and old.get("complete"):
        old["reused_from_previous_run"] = True
        old["other_code"] = old.get("code") != code_sha256()
        return old
    if not owned_by_doefab(out, STAGE_KIND, stage=name):  # prepare_scene refuses this before any work
        raise DoefabError(f"{out} is not a doefab {name} stage folder (no ownership marker): move it away")
    # an interrupted run of the same inputs keeps what it had saved (RESUMABLE); everything else is removed in
    # place (nothing is moved, so an interruption here loses nothing)
    same = not force and old.get("hash") == h
    keep = [f for f in RESUMABLE.get(name, ()) if same and (out / f).exists()]
    out.mkdir(parents=True, exist_ok=True)
    theirs = foreign_entries(out, old)
    clear_stage(out, set(keep) | {MARKER}, theirs)
    if theirs:
        print(f"[doefab run] {name}: kept what doefab did not write in {out}: {', '.join(sorted(theirs))}",
              flush=True)
    mark_folder(out, STAGE_KIND, stage=name)
    info_resumed = bool(keep)
    atomic_write_json(rec_path, {"stage": name, "hash": h, "complete": False, "foreign": sorted(theirs)})
    t = time.perf_counter()
    info = STAGE_FUNCS[name](scene, res, out, quick)
    if info_resumed:
        info["why"] = info.get("why", "") + f"; continued from the interrupted run's {', '.join(keep)}"
    mark_folder(out, STAGE_KIND, stage=name)
    info.update(stage=name, hash=h, code=code_sha256(), seconds=round(time.perf_counter() - t, 2), complete=True,
                files=sorted(set(stage_files(out)) - theirs - {"stage.json", MARKER}))
    atomic_write_json(rec_path, info)
    return info


def stage_files(out: Path) -> list[str]:
    """Every file under stage folder ``out``, as a path relative to it ('/'-separated)."""
    return sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() or p.is_symlink())


def foreign_entries(out: Path, record: dict) -> set[str]:
    """The files under stage folder ``out`` (relative paths, subfolders included) that doefab did not write:
    those missing from the last finished run's ``files`` list, and those an interrupted run recorded as not its
    own (``foreign``). A record without a list (a run made before stages listed their files) names none."""
    if not out.is_dir():
        return set()
    # file names as written (``read_json`` reads a file named "nan" or "inf" back as a number)
    theirs = {str(f) for f in record.get("foreign") or ()}
    if isinstance(record.get("files"), list):
        ours = {str(f) for f in record["files"]} | {"stage.json", MARKER}
        theirs |= {f for f in stage_files(out) if f not in ours}
    return {f for f in theirs if (out / f).exists()}


def clear_stage(out: Path, keep_top: set, theirs: set) -> None:
    """Remove what doefab wrote under ``out`` in place (nothing is moved, so an interruption loses nothing): every
    file but those under a top-level name in ``keep_top`` and the user's ``theirs``; then the folders left empty."""
    for f in stage_files(out):
        if f.split("/")[0] not in keep_top and f not in theirs:
            (out / f).unlink()
    for d in sorted((p for p in out.rglob("*") if p.is_dir() and not p.is_symlink()), key=lambda p: -len(p.parts)):
        if d.relative_to(out).parts[0] not in keep_top and not any(d.iterdir()):
            d.rmdir()
