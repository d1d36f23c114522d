"""The stages of ``doefab run``: each writes its own folder, records what it did and why, and is reused when
its inputs (a content hash of its scene section and its upstream stages' hashes) have not changed.

A scene whose design settings equal a committed design (``masks/<design>/design``) reuses that design, its
verified mask set and its shipped networks instead of recomputing them.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

from doefab.applications import has
from doefab.diekey import DEFAULT_THICKNESS_MM
from doefab.errors import DoefabError
from doefab.io import MARKER, atomic_write_json, read_json
from doefab.pipeline.resolved import ResolvedScene
from doefab.pipeline.scenekeys import WEIGHTS_MODES, weights_mode
from doefab.pipeline.sceneholder import scene_die, scene_holder
from doefab.pipeline.system import quick_sampling, resolve, scene_camera, scene_sensor, shipped_sensor_differs

__all__ = ["resolve", "REPO", "redesign_note", "design_arguments", "quick_sampling", "stage_design", "stage_masks",
           "stage_holder", "stage_reconstruction", "stage_tolerance", "repo_mask_set", "networks_trained_here",
           "shipped_sensor_differs", "QUICK", "quick_note"]

#: the numbers ``doefab run --quick`` cuts (the stages read them, the report's ``quick_note`` says them): design
#: iterations at most, the networks' training minutes each and the fabricated parts their training captures draw,
#: the reconstruction table's and the tolerance judge's scenes and their side, the Monte Carlo's parts and the
#: tornado's errors judged through the network; besides, a quick run skips the quantization study, the holder's
#: STEP file and KLayout's mask check
QUICK = {"design_iterations": 10, "train_minutes": 0.2, "train_parts": 2, "images": 2, "size_px": 128, "parts": 3,
         "network_top": 2}

REPO = Path(__file__).resolve().parents[2]


def _design_run(settings: dict, quick: bool, quick_factor: int | None = None) -> tuple[int, int]:
    """(iterations, sampling) of the design stage's run for these settings (quick: at most 10 iterations on a grid
    about 4× coarser, by ``quick_factor``: the factor ``resolve`` found that divides the grid and keeps the PSF
    routes' sampling, ``system.quick_sampling``)."""
    iters = min(int(settings["iterations"]), QUICK["design_iterations"]) if quick else int(settings["iterations"])
    sampling = int(settings["sampling"])
    if quick:
        sampling = quick_factor if quick_factor is not None else quick_sampling(
            int(settings["camera"]["doe_pixels"]), sampling)
    return iters, sampling


def quick_note(done: dict | None = None) -> str:
    """What the report of a ``--quick`` run says first: what the flag cut (``QUICK``) in the stages that ran
    (``done``: the run's stage records; None: every cut) and that its numbers show every stage running, not what
    the design or its parts deliver."""
    q = QUICK
    done = done if done is not None else {s: {"status": "ran", "weights": "train"} for s in
                                          ("design", "masks", "holder", "reconstruction", "tolerance")}
    ran = {name for name, rec in done.items() if (rec or {}).get("status") != "skipped"}  # reused or kept: ran
    cuts = []
    if (done.get("design") or {}).get("status") == "ran":
        cuts.append(f"a new design at most {q['design_iterations']} iterations, on a coarser grid where a factor "
                    f"divides the DOE grid")
    rec = done.get("reconstruction") or {}
    if "reconstruction" in ran and rec.get("weights") in WEIGHTS_MODES and weights_mode(rec["weights"]).trains:
        cuts.append(f"networks trained here {60 * q['train_minutes']:.0f} s each")
    judged = [w for w, s in (("the reconstruction table", "reconstruction"), ("each judged part", "tolerance"))
              if s in ran]
    if judged:
        cuts.append(f"{' and '.join(judged)} on {q['images']} scenes of {q['size_px']}² px")
    if "tolerance" in ran:
        cuts.append(f"{q['parts']} Monte Carlo parts; no quantization study")
    cuts += [c for c, s in (("no STEP file", "holder"), ("no KLayout mask check", "masks")) if s in ran]
    return (f"**A quick run** (`doefab run --quick`): {'; '.join(cuts)}. It shows that every stage runs on this "
            f"scene; its numbers are not what the design or its parts deliver: run without --quick for those.")


def design_arguments(res: ResolvedScene, quick: bool = False) -> dict:
    """The arguments of ``doefab.optimize`` (and ``design.pace.design_time``) for the scene's new design: its task,
    steps, grid (``_design_run``), the task's bands, planes and geometry bound to its camera, and the rest of its
    settings."""
    s = res.settings
    iters, sampling = _design_run(s, quick, res.quick_sampling)
    return {"task": s["design_task"], "iterations": iters, "optimizer": s["optimizer"], "seed": s["seed"],
            "camera": res.camera, "sampling": sampling, "task_params": res.task.params(),
            "parameterization": s["parameterization"], "knots": int(s["knots"]), "n_levels": int(s["n_levels"])}


def redesign_note(res: ResolvedScene, quick: bool) -> str:
    """One line: why the committed design is not reused, what the new one runs (steps, grid), where its run time
    is measured beforehand (``doefab doctor``, which times the full run, not ``--quick``'s) and how large its
    checkpoint grows."""
    s = res.settings
    why = "; ".join(k if isinstance(s[k], (dict, list)) else f"{k} {s[k]} (committed {c})"
                    for k, c in ((k, res.committed_settings[k]) for k in res.differ))
    iters, sampling = _design_run(s, quick, res.quick_sampling)
    grid = s["camera"]["doe_pixels"] // sampling
    ckpt = ""
    if s["parameterization"] == "pixel":  # the phase map and Adam's two moments, float32
        ckpt = f"; checkpoint ~{3 * 4 * grid**2 / 1e6:.0f} MB"
    timed = "" if quick else "; doefab doctor measures its run time on this machine beforehand"
    return (f"the committed {s['design_task']} design is not reused: the scene sets {why}; a new design is optimised "
            f"({iters} {s['optimizer']} iterations on a {grid}² grid{timed}{ckpt})")


def _copy_design(src: Path, dst: Path) -> None:
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("design.json", "levels.npy", "height.npy", "history.csv"):
        if (src / f).is_file():
            shutil.copyfile(src / f, dst / f)


def stage_design(scene, res, out: Path, quick: bool) -> dict:
    import torch

    import doefab
    from doefab.design.design import Design
    from doefab.plotting import design_psf_figure, plot_height

    if res.reuse:
        _copy_design(res.committed_dir, out)
        older = ("; optimised on an earlier metric and kept with the networks trained for it (its design.json's "
                 "metrics.optimised_on)" if "optimised_on" in res.committed.metrics else "")
        info = {"status": "reused", "why": f"the scene's design settings equal the committed design "
                                          f"{res.settings['design_task']} (shipped with doefab){older}"}
    else:
        print(f"[doefab run] design: {redesign_note(res, quick)}", flush=True)
        args = design_arguments(res, quick)
        iters, sampling = args["iterations"], args["sampling"]
        d = doefab.optimize(**args, out_dir=out, progress=True,
                            resume=(out / "checkpoint.pt").is_file())  # an interrupted run's, same inputs
        d.save(out)
        info = {"status": "ran", "why": f"settings differ from the committed design in {', '.join(res.differ)}"
                + (f" (quick: {iters} iterations on a {sampling}× coarser grid)" if quick else "")}
    d = Design.load(out)
    d.write_level_image(out)  # a reused design's too (the repository keeps its levels.npy only)
    task = res.task
    plan = doefab.PSFPlan(d.camera, d.wavelengths, d.depths, task.kernel_size, halves=("coded",))
    with torch.no_grad():
        psf = plan(doefab.levels_to_height(d.levels, d.camera, d.n_levels)).coded.numpy()
    design_psf_figure(out / "psf_target_vs_design.png", d, psf, task.targets(d.camera).numpy())  # log scale
    plot_height(out / "height_map.png", doefab.levels_to_height(d.levels, d.camera, d.n_levels), d.camera.doe_pitch,
                f"{d.n_levels}-level height map")
    info["metric"] = d.metrics
    return info


def stage_masks(scene, res, out: Path, quick: bool) -> dict:
    from doefab.design.design import Design
    from doefab.fabrication.export import MaskOptions, export_masks
    from doefab.fabrication.verify import verify_mask_set

    design_dir = out.parent / "design"
    fab = scene.fabrication
    chamfer, thickness = scene_die(scene)
    committed_set = repo_mask_set(res, chamfer, thickness)
    if committed_set is not None and fab.get("pattern_faces", "lens") == "lens":
        t = time.perf_counter()
        copy_mask_set(committed_set, out)
        rep = verify_mask_set(out, use_klayout=not quick)  # the copy this run hands over is the one verified
        atomic_write_json(out / "verification.json", rep)
        return {"status": "reused", "why": f"the committed mask set {committed_set} (same design), copied here "
                                           f"whole and re-verified in {time.perf_counter() - t:.1f} s",
                "mask_set": str(out)}
    d = Design.load(design_dir)
    opts = MaskOptions(name=d.task.replace("-", ""), oasis=bool(fab.get("oasis", False)), die_m=res.die_m,
                       die_chamfer_m=chamfer, substrate_thickness_m=thickness,
                       pattern_faces=fab.get("pattern_faces", "lens"), use_klayout=not quick)
    # the export writes a fresh folder of its own beside the stage folder, then moves in (run_stage marks it again)
    tmp = out.parent / f".{out.name}.export"
    if tmp.exists():
        shutil.rmtree(tmp)
    export_masks(d, tmp, opts, design_dir=design_dir)
    for f in tmp.iterdir():
        os.replace(f, out / f.name)
    tmp.rmdir()
    why = ("the design is new (or its pattern side differs)" if not res.reuse else
           "the committed mask set is not in this installation (it lives in the repository): exported afresh")
    return {"status": "ran", "why": why, "mask_set": str(out)}


def copy_mask_set(src: Path, out: Path) -> None:
    """Copy a mask set's files (layouts, manifest, README for the fab, previews, its design) into ``out``, each
    written under a temporary name and renamed, so the run's masks folder is a whole mask set of its own."""
    out.mkdir(parents=True, exist_ok=True)
    for f in sorted(src.rglob("*")):
        if f.is_dir() or f.name == MARKER:
            continue
        dst = out / f.relative_to(src)
        dst.parent.mkdir(parents=True, exist_ok=True)
        tmp = dst.with_name(f".{dst.name}.copy")
        shutil.copyfile(f, tmp)
        os.replace(tmp, dst)


def repo_mask_set(res: ResolvedScene, die_chamfer_m: float, thickness_m: float) -> Path | None:
    """The repository's committed mask set of a reused design (``masks/<design>``), when this is a checkout that
    has it, its level map is the design's and its die (side, key ``die_chamfer_m`` and substrate ``thickness_m``)
    the scene's holder's; None otherwise (an installed package exports the masks itself)."""
    if not res.reuse:
        return None
    folder = REPO / "masks" / res.settings["design_task"]
    from doefab.design.design import Design, levels_sha256

    try:
        same = levels_sha256(Design.load(folder / "design").levels) == levels_sha256(res.committed.levels)
        man = read_json(folder / "manifest.json")
    except (DoefabError, OSError, ValueError):  # no mask set here (an installed package), or a damaged one
        return None
    die = tuple(round(man.get(k, 0.0) * 1e9) for k in ("die_m", "die_chamfer_m"))
    die += (round(man.get("substrate_thickness_m", DEFAULT_THICKNESS_MM * 1e-3) * 1e9),)  # older sets: 1 mm
    return folder if same and die == tuple(round(v * 1e9) for v in (res.die_m, die_chamfer_m, thickness_m)) else None


def stage_holder(scene, res, out: Path, quick: bool) -> dict:
    from holder_cad.build import write_holder
    from holder_cad.params import HolderParams

    params = HolderParams(**scene_holder(scene, res.camera if res is not None else scene_camera(scene)))
    rep = write_holder(params, out, step=False if quick else None, renders=True)
    horizontal = getattr(res, "split", None) == "horizontal"  # res None: a holder without a resolved scene
    turn = ("; the sensor's dual-pixel split is horizontal: mount the die turned by 90° (index notches at 3 and "
            "9 o'clock) so the DOE's split line lies along the sensor's" if horizontal else "")
    # the build's own warnings (a layout wider than a common bed); the thread's reach the run's warnings already
    built = [w for w in rep["warnings"] if w not in params.warnings]
    return {"status": "ran", "why": "parametric part (0.5 s mesh path)" + ("; STEP skipped (quick)" if quick else "")
            + turn + "".join(f"; warning: {w}" for w in built), "doe_to_lens_mm": rep["doe_to_lens_mm"],
            "files": rep["files"]}


def stage_reconstruction(scene, res, out: Path, quick: bool) -> dict:
    """The three networks of the scene's design evaluated on held-out test scenes captured through fabricated
    parts: the shipped ones for a committed design, networks trained here for a new one (``weights = "train"``,
    warm-started from the shipped ones where shapes match), or the shipped ones on a new design's captures
    (``"shipped-anyway"``: told its PSFs, flagged in the report)."""
    from doefab.reconstruction.evaluate import evaluate
    from doefab.tolerance.conditions import for_splits

    rec, task = scene.reconstruction, scene.task
    mode = weights_mode(rec.get("weights"))
    design = None if res.reuse else out.parent / "design"
    sensor = res.sensor  # None: the default sensor
    if design is not None and not mode.any_system:
        return {"status": "skipped", "why": f"the shipped networks are trained for the committed "
                                            f"{res.settings['design_task']} design, not this scene's: set "
                                            f"reconstruction.weights = \"train\" to train networks for it, or "
                                            f"\"shipped-anyway\" to evaluate the shipped ones on its captures"}
    other_sensor = shipped_sensor_differs(task, sensor)
    if other_sensor and not mode.any_system:
        return {"status": "skipped", "why": f"the shipped networks are trained for another sensor ("
                                            f"{'; '.join(other_sensor)}): set reconstruction.weights = \"train\" "
                                            f"to train networks for this camera, or \"shipped-anyway\" to evaluate "
                                            f"the shipped ones on its captures"}
    budget = _scene_budget(scene)
    parts = 2
    weights_dir, warm = None, {}
    if mode.trains:
        from doefab.reconstruction.train import train
        from doefab.reconstruction.weights import WEIGHTS_DIR

        weights_dir = out / "weights"
        minutes = QUICK["train_minutes"] if quick else float(rec.get("minutes", 6))
        cond = for_splits(task, design, "honest", ("train", "val"), QUICK["train_parts"] if quick else 6,
                          budget=budget)
        for v in ("proposed", "coded_only", "uncoded_only"):
            run_dir = out / f"run_{v}"
            r = train(task, v, minutes, run_dir, weights_dir=weights_dir, design=design, conditions=cond, sensor=sensor,
                      warm_start=WEIGHTS_DIR, progress=True, val_images=QUICK["images"] if quick else 8,
                      resume=(run_dir / "checkpoint.pt").is_file())  # an interrupted run's, same inputs
            warm[v] = r["training"]["warm_start"]
    images = QUICK["images"] if quick else int(rec.get("images", 4))
    size = QUICK["size_px"] if quick else int(rec.get("size_px", 256))
    cond = for_splits(task, design, "honest", ("test",), parts, budget=budget)["test"]
    r = evaluate(task, out, images=images, size=size, weights_dir=weights_dir, design=design, conditions=cond,
                 other_design=mode.flagged, sensor=sensor, split="test")
    why = ("trained here for this design (" + ", ".join(
        f"{v}: {w['tensors']}/{w['of']} tensors warm-started from the shipped network" if w else
        f"{v}: continued from its checkpoint" for v, w in warm.items()) + ")" if mode.trains else
        "WARNING: the shipped networks, trained for the committed design and the default sensor, evaluated on "
        "this system's captures (told its PSFs); train networks for it for fair numbers" if mode.flagged else
        "shipped networks of the committed design")
    return {"status": "ran" if weights_dir else "reused",
            "why": why + f"; evaluated on {images} held-out scenes of {size}² px from the test split (not the final "
                         f"test set, which only doefab evaluate --split final reads), captured through {parts} "
                         f"fabricated parts with crosstalk unmixed by a noisy calibration (the network told the "
                         f"nominal PSF) and recorded by this camera's sensor ({_sensor_text(sensor, task)})",
            "rows": r["rows"], "by_light": r.get("by_light"), "weights": mode.name, "split": r["split"],
            "design_levels_sha256": _design_sha(out.parent / "design")}


def networks_trained_here(scene, res, root: Path) -> tuple[Path | None, str]:
    """The networks the reconstruction stage of the run in ``root`` trained (``weights = "train"``), when the
    loader's check (``reconstruction.loader.weights_record``) finds them trained for the design in
    ``root/design`` and the scene's sensor: (their folder, "") or (None, why none: "" where it trained none)."""
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.loader import weights_record

    folder = root / "reconstruction"
    try:
        rec = read_json(folder / "stage.json")
    except (OSError, ValueError):
        return None, ""
    mode = WEIGHTS_MODES.get(rec.get("weights")) if isinstance(rec, dict) else None
    if mode is None or not mode.trains or not (folder / "weights").is_dir():  # an unfinished record has no mode
        return None, ""
    try:
        weights_record(scene.task, "proposed", folder / "weights", root / "design", res.sensor or Sensor())
    except DoefabError as exc:
        return None, (f"not judged through the networks in {folder / 'weights'}: {exc}; or run the reconstruction "
                      f"stage (\"reconstruction\" in stages, weights = \"train\") to train networks for this "
                      f"design and sensor")
    return folder / "weights", ""


def _sensor_text(sensor, task: str) -> str:
    from doefab.imaging.sensor import Sensor

    return (sensor or Sensor()).describe(with_response=has(task, "spectral"))


def _scene_budget(scene) -> dict | None:
    """The scene's tolerance budget (None without a [tolerance] section: the shipped one)."""
    if getattr(scene, "tolerance", None) is None:
        return None
    from doefab.tolerance.errors import load_budget

    return load_budget(scene.budget_path())


def _design_sha(folder: Path) -> str:
    from doefab.design.design import Design, levels_sha256

    return levels_sha256(Design.load(folder).levels)


def _mounting_note(holder_built: bool, budget_path, budget: dict) -> str:
    """Where the study's mounting errors (decenter, rotation, tilt, gap) come from: the holder this run built, the
    scene's own budget, or the shipped budget's, which are a 3D-printed filter-thread holder's (a phone or a lens
    without a filter thread is mounted otherwise: the note names the key to change). ``budget``: as
    ``load_budget(budget_path)`` read it (its ``defaults_used``: the keys a budget of the scene's own left out)."""
    from doefab.tolerance.errors import is_shipped_budget

    if holder_built:
        return "; mounting errors from this run's holder"
    shipped = is_shipped_budget(budget_path)
    left = [k for k in budget.get("defaults_used", []) if k.startswith("mounting.")]
    if not shipped and not left:
        return ""
    which = "mounting errors" if shipped else f"{', '.join(left)} (left out of {Path(budget_path).name})"
    return (f"; {which} from the shipped budget's 3D-printed filter-thread holder (no holder built in this run): "
            f"where the DOE is mounted otherwise, set tolerance.budget to a budget of that mount")


def stage_tolerance(scene, res, out: Path, quick: bool) -> dict:
    """The scene's part judged through its task's network: delivered quality, its yield against the budget's
    [spec], a tornado in delivered terms for the errors that matter most, the grid each error needs; the
    quantization study at PSF level. A rerun after an interruption continues from the saved parts."""
    from doefab.tolerance.errors import holder_mounting, load_budget, with_sensor_noise
    from doefab.tolerance.netjudge import SCENES
    from doefab.tolerance.report import run_study

    tol = scene.tolerance
    if tol is None:
        return {"status": "skipped", "why": "the scene has no [tolerance] budget: no Monte Carlo"}
    path = scene.budget_path()
    budget = load_budget(path)
    holder = out.parent / "holder" / "holder.json"
    if holder.is_file():  # the mounting errors of the holder this scene built
        budget.setdefault("mounting", {}).update(holder_mounting(holder))
    with_sensor_noise(budget, scene_sensor(scene))  # the PSF-level judge's crosstalk calibration draws it
    samples = QUICK["parts"] if quick else int(tol.get("samples", 20))
    own, stale = networks_trained_here(scene, res, out.parent)  # before the shipped ones, which fit one system
    shipped_fits = own is None and res.reuse and not shipped_sensor_differs(scene.task, res.sensor)
    networks = own is not None or shipped_fits
    # the parts' captures: the reconstruction table's split and scene size (``netjudge``), SCENES per part
    judge = {"images": QUICK["images"] if quick else SCENES,
             "size": QUICK["size_px"] if quick else int(scene.reconstruction.get("size_px", 256)),
             "split": "test"}
    out.mkdir(parents=True, exist_ok=True)
    r = run_study(out.parent / "design", budget, out, samples=samples, seed=0,
                  grid=int(tol["supersample"]) if "supersample" in tol else "auto", do_levels=not quick,
                  budget_path=path, networks=judge if networks else False,
                  weights_dir=own,
                  network_top=QUICK["network_top"] if quick else 5, workers=tol.get("workers"),
                  scheduler=tol.get("scheduler"))
    through = ("through the networks this scene trained" if own else "through the shipped networks" if networks
               else "at PSF level (no network for this system)")
    return {"status": "ran", "why": f"{samples} Monte Carlo parts {through}"
            + ("" if quick else " and the quantization study")
            + _mounting_note(holder.is_file(), path, budget)
            + (f"; {stale}" if stale else "")
            + ("" if networks or not res.reuse else "; the shipped networks are for another sensor")
            + ("" if not networks else f"; each part judged on {judge['images']} test scenes of {judge['size']}² px "
                                        f"(the reconstruction table's split and size) captured by the sensor its "
                                        f"network was trained for"),
            "summary": r.get("summary"), "level": r["level"]}
