"""Run the requested studies and write tolerance.json, report.md and the figures.

The report opens with what a user acts on: what the part delivers (mean and interval), its yield against the
spec (Wilson interval), the errors that limit it and what would buy the most; then the grid each error was
judged on, the tornado, the Monte Carlo, the surrogate and the quantization study.
"""

from __future__ import annotations

import math
import time
from functools import partial
from pathlib import Path

import numpy as np

from doefab.io import atomic_write_json, atomic_write_text, json_ready
from doefab.tolerance import plots, study
from doefab.tolerance.delivered import change_noise
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.kinds import KINDS
from doefab.tolerance.partmemo import IN_PART, STEPS, cached_step, memo_step
from doefab.tolerance.reporttext import REMEDY, body_lines, lead_text, spec_words, summary_lines

__all__ = ["run_study", "REMEDY", "summary_lines"]

SURROGATE_SEED = 987_654  # the surrogate's own parts: spawn key (0,) calibrates it, (1,) validates it
CALIBRATION_PARTS = 16
HOLDOUT_PARTS = 16  # validation parts, where the study has fewer direct Monte Carlo parts than this


def run_study(design_dir: Path, budget: dict, out: Path, samples: int = 20, seed: int = 0, grid="auto",
              do_sweep: bool = False, do_levels: bool = False, workers: int | None = None, scheduler=None,
              budget_path=None, networks: bool = False, surrogate: bool = False, weights_dir=None,
              progress: bool = True, network_top: int | None = None, fresh: bool = False) -> dict:
    """All requested studies of one design; returns what ``tolerance.json`` holds. ``network_top``: judge only
    the tornado's largest errors (at PSF level) through the network. ``workers``: local processes for the
    Monte Carlo (None: one per core when there are enough parts); ``scheduler``: a Dask scheduler instead
    (``schedulers.parse_scheduler``; a ``tcp://`` one must answer before any work). ``networks``: False, True (the
    network judge's default scenes) or the judge's scenes (``netjudge.judge_settings``: images, size, split).
    ``fresh``: an earlier study's parts, steps and results in ``out`` are removed, once the design is read and
    before any part is judged (a study refused before that keeps them)."""
    from doefab._memory import keep_freed_memory
    from doefab.applications import of_design
    from doefab.tolerance.montecarlo import check_resumable
    from doefab.tolerance.mounted import stop_case
    from doefab.tolerance.netjudge import judge_settings
    from doefab.tolerance.spec import limits_text, nominal_failures

    _check_runners(workers, scheduler)
    keep_freed_memory()

    out = Path(out)
    judge = study.judge_for(str(design_dir), 1)
    _open_folder(out, fresh, samples > 0, lambda: check_resumable(out, judge.design, budget, seed, grid, networks,
                                                                  weights_dir, judge.chain))
    task = getattr(of_design(judge.design.task), "name", judge.design.task)
    spec = budget.get("spec", {})
    res: dict = {"design": str(design_dir), "task": task, "seed": seed, "stop": stop_case(judge.fine),
                 "n_levels": judge.design.n_levels,
                 "budget_file": str(budget_path or "doefab/tolerance/budget.toml (default)"), "budget": budget,
                 "level": "network" if networks else "psf"}
    if networks:
        res["network_judge"] = judge_settings(networks)  # the scenes every part is judged on
    res["nominal"] = {"psf": {"psf_metric": judge.score(judge.nominal)["metric"]}}
    key = _step_key(judge, budget, grid, networks, weights_dir, network_top)
    res["steps_reused"] = reused = []
    if networks:
        nom = cached_step(out, "nominal_network", key, lambda: {k: v for k, v in study.evaluate_part(
            str(design_dir), 1, PartErrors().to_json(), networks, weights_dir).items() if k.startswith("network")},
            reused)
        res["nominal"]["network"], res["nominal"]["network_scenes"] = nom["network"], nom["network_scenes"]
    res["warnings"] = [f"the nominal part already fails the spec ({w}): no part can meet it"
                       for lvl in ("psf", "network") if lvl in res["nominal"] or lvl == "psf"
                       for w in nominal_failures(spec, task, lvl, _flat_nominal(res["nominal"], lvl))]
    res["spec"] = {lvl: _limits(spec, task, lvl, res["nominal"], limits_text) for lvl in ("psf", "network")}
    # limits relative to the error-free part differ per label: each label's parts are judged against its own
    res["spec_by_label"] = {label: _limits(spec, task, "network", {"network": {"nominal_psf": nom}}, limits_text)
                            for label, nom in res["nominal"].get("network", {}).items()}
    res["grid"] = memo_step(out, "grid", key, reused, lambda memo: _grid_record(judge, budget, grid, progress, memo))
    grids = ({k: v["grid"] for k, v in res["grid"]["kinds"].items()} if grid == "auto" else
             {k.name: int(grid) for k in KINDS})
    mc_grid = res["grid"]["monte_carlo_grid"]
    _require_memory(judge, mc_grid, res["grid"], workers, scheduler)
    t = time.perf_counter()
    res["tornado"] = memo_step(out, "tornado", _tornado_key(key, networks), reused,
                               lambda memo: study.tornado(design_dir, budget, grids, networks, weights_dir, progress,
                                                          network_top, evaluate=memo))
    res["tornado_seconds"] = None if "tornado" in reused else round(time.perf_counter() - t, 1)
    for r in res["tornado"]:  # each delivered change's scene noise, from its paired per-scene changes
        if "network_delta_scenes" in r:
            r["network_delta_ci95"] = change_noise(r["network_delta_scenes"])
    if do_sweep:
        t, res["sweeps"] = time.perf_counter(), memo_step(out, "sweeps", key, reused, lambda memo: study.sweep(
            design_dir, grids, progress=progress, keep=memo.keep)["sweeps"])
        res["sweep_seconds"] = None if "sweeps" in reused else round(time.perf_counter() - t, 1)
    if samples > 0:
        _monte_carlo(res, design_dir, budget, out, samples, seed, mc_grid, scheduler, workers, networks, spec,
                     task, progress, weights_dir)
    if surrogate:  # fitted once per study; validated on the Monte Carlo's parts as they stand
        res["surrogate"] = _surrogate(out, key, reused, res, design_dir, budget, mc_grid, spec, task, progress)
    if do_levels:
        res["quantization"] = _quantization(out, key, reused, judge, design_dir, mc_grid, networks, weights_dir,
                                            progress)
    _figures(out, res)
    atomic_write_json(out / "tolerance.json", res)
    atomic_write_text(out / "report.md", "\n".join(_markdown(res)) + "\n")
    return res


def _quantization(out, key, reused, judge, design_dir, grid, networks, weights_dir, progress) -> list[dict]:
    """The quantization study's rows on ``grid``, kept level count by level count (``memo_step``) under the study's
    key, the grid and the design's continuous heights (which the folder's level map does not fix), with each
    network-judged row's change from the design's own level count."""
    import hashlib

    height = study.continuous_height(judge.design)
    digest = None if height is None else hashlib.sha256(np.ascontiguousarray(height, np.float64).tobytes()).hexdigest()
    rows = memo_step(out, "quantization", {**key, "grid": grid, "continuous_height_sha256": digest}, reused,
                     lambda memo: study.quantization_study(design_dir, supersample=grid, networks=networks,
                                                           weights_dir=weights_dir, progress=progress, keep=memo.keep))
    _level_changes(rows, judge.design.n_levels)
    return rows


def _level_changes(rows: list, n_levels: int) -> None:
    """Each network-judged quantization row's delivered change from the design's own level count on the same
    scenes (``network_delta``) and its paired 95 % interval's half-width (``network_delta_ci95``)."""
    ref = next((r for r in rows if r["levels"] == n_levels and "network_scenes" in r), None)
    if ref is None:
        return
    for r in rows:
        if "network_scenes" in r and r is not ref:
            r["network_delta"], changes = study.network_changes(r, ref)
            r["network_delta_ci95"] = change_noise(changes)


def _flat_nominal(nominal: dict, level: str) -> dict:
    """The nominal part's values a spec at ``level`` compares with (network: given the nominal PSF)."""
    if level == "psf":
        return nominal["psf"]
    return nominal.get("network", {}).get("nominal_psf", {})


def _limits(spec, task, level, nominal, limits_text) -> str | None:
    from doefab.errors import DoefabError

    try:
        return limits_text(spec, task, level, _flat_nominal(nominal, level))
    except DoefabError:
        return None


def _grid_record(judge, budget, grid, progress, memo=None) -> dict:
    """Per-kind grids: measured on the design (``grid="auto"``; each kind kept by ``memo``) or one grid for all."""
    from doefab.tolerance.grid import grid_study

    if grid == "auto":
        t = time.perf_counter()
        rec = grid_study(judge, budget, progress=progress, keep=None if memo is None else memo.keep)
        rec["seconds"] = round(time.perf_counter() - t, 1)
        return rec
    return {"monte_carlo_grid": int(grid), "kinds": {}, "fixed": True}


def _open_folder(out: Path, fresh: bool, resumes: bool, check) -> None:
    """The study's folder: ``fresh``, no saved parts, no finished steps and no results of an earlier study in it (a
    user's other files stay); where the study has parts to judge (``resumes``), ``check()`` refuses a resume of
    another study before any step is judged or replaced."""
    import shutil

    if fresh:
        for f in ("samples.jsonl", *RESULT_FILES):
            (out / f).unlink(missing_ok=True)
        shutil.rmtree(out / STEPS, ignore_errors=True)
    if resumes:
        check()


def _check_runners(workers, scheduler) -> None:
    """Where the Monte Carlo's parts run, as the API was told: ``workers`` (1..``MAX_WORKERS``) or a ``scheduler``
    that parses and, for ``tcp://``, answers; not both."""
    from doefab.errors import DoefabError
    from doefab.tolerance.schedulers import MAX_WORKERS, check_reachable, runner_conflict

    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or not 1 <= workers <= MAX_WORKERS):
        raise DoefabError(f"workers = {workers!r}: give a whole number of processes, 1..{MAX_WORKERS}, or None (one "
                          f"per core when there are enough parts)")
    both = runner_conflict(workers, scheduler)
    if both:
        raise DoefabError(both)
    check_reachable(scheduler, "scheduler")


def _require_memory(judge, grid: int, record: dict, workers, scheduler) -> None:
    """``fields.require_memory`` for the design of ``judge`` on ``grid`` (the tornado judges its parts in this
    process; the Monte Carlo's ``workers`` or ``local:N`` Dask workers judge that many at once here, a ``tcp://``
    cluster's elsewhere), with the grid study's bounds (the largest over its error kinds at each grid) from
    ``record``."""
    from doefab.tolerance.fields import part_size, require_memory
    from doefab.tolerance.grid import GRIDS
    from doefab.tolerance.schedulers import parts_at_once

    bounds: dict = {}
    for v in record.get("kinds", {}).values():
        for s, b in v.get("bound", {}).items():
            bounds[int(s)] = max(bounds.get(int(s), 0.0), float(b))
    require_memory(part_size(judge.design, judge.n_masks), grid, GRIDS, bounds, parts=parts_at_once(workers, scheduler))


# what a finished study writes beside samples.jsonl and steps/ (``run_study``, ``_figures``)
RESULT_FILES = ("tolerance.json", "report.md", "tornado.png", "sweeps.png", "quantization.png", "yield_vs_n.png",
                "delivered.png")


def _step_key(judge, budget, grid, networks, weights_dir, network_top) -> dict:
    from doefab.tolerance.kinds import KINDS
    from doefab.tolerance.montecarlo import run_identity

    return {**run_identity(judge.design, budget, 0, 1, networks, weights_dir, judge.chain), "grid_arg": str(grid),
            "network_top": network_top, "weights_dir": None if weights_dir is None else str(Path(weights_dir).resolve()),
            "kind_magnitudes": {k.name: k.from_budget(budget) for k in KINDS}}  # what each error is judged at


def _tornado_key(key: dict, networks) -> dict:
    """The tornado step's key: the study's, marked where it judges its top errors through the network
    (``network_top``) on other scenes than the defaults. Such tornadoes kept before the mark were judged on the
    default scenes whatever the study asked for, and are computed again."""
    from doefab.tolerance.netjudge import judge_settings

    if networks and key.get("network_top") is not None and judge_settings(networks) != judge_settings(True):
        return {**key, "tornado_scenes": "the study's"}
    return key


def _monte_carlo(res, design_dir, budget, out, samples, seed, grid, scheduler, workers, networks, spec, task,
                 progress, weights_dir=None) -> None:
    from doefab.tolerance.montecarlo import monte_carlo
    from doefab.tolerance.yieldstats import summarize, wilson
    from doefab.tolerance.spec import meets

    t = time.perf_counter()
    rows = monte_carlo(design_dir, budget, samples, out, seed=seed, supersample=grid, scheduler=scheduler,
                       workers=workers, progress=progress, networks=networks, weights_dir=weights_dir)
    res["monte_carlo_seconds"] = round(time.perf_counter() - t, 1)
    res["parts_per_minute"] = round(samples * 60 / max(res["monte_carlo_seconds"], 1e-9), 2)
    res["samples"] = rows
    nominal = {"psf": res["nominal"]["psf"], "network": res["nominal"].get("network", {})}
    res["summary"] = summarize(rows, spec, task, nominal)
    if networks:  # the delivered quality's mean and yield with the scenes' noise, and that noise against the spread
        from doefab.tolerance.delivered import delivered_summary

        res["summary"]["delivered"] = delivered_summary(rows, res["nominal"]["network_scenes"], spec, task, seed)
    conv = []
    for n in sorted({k for k in (5, 10, 20, 40, 80, 160, 320, 640, samples) if 2 <= k <= samples}):
        ok = [meets({"psf_metric": r["metric"]}, spec, task, "psf", res["nominal"]["psf"]) for r in rows[:n]]
        lo, hi = wilson(sum(ok), n)
        conv.append({"n": n, "yield": float(np.mean(ok)), "yield_ci95": [lo, hi], "yield_ci95_width": hi - lo,
                     "seconds": max(r["seconds"] for r in rows[:n])})
    res["convergence"] = conv


def _surrogate(out, key, reused, res, design_dir, budget, grid, spec, task, progress) -> dict:
    """The surrogate on ``grid``: fitted and calibrated on parts of its own, with its yield (the step "surrogate",
    kept under the study's ``key`` and the grid, so a resumed study with more Monte Carlo parts does not fit it
    again), and validated on parts it never saw: the direct Monte Carlo's where the study has at least
    ``HOLDOUT_PARTS`` (``res["samples"]``, paired part by part, read afresh each run), else held-out parts of its
    own (the step "surrogate_holdout"). Each part it judges is kept (``memo_step``): an interrupted step resumes
    with them."""
    from doefab.tolerance.spec import spec_limits
    from doefab.tolerance.surrogate import validate

    judge = study.judge_for(str(design_dir), grid)
    limit = max((lim for _, _, lim, _ in spec_limits(spec, task, "psf", res["nominal"]["psf"])), default=-math.inf)
    step_key = {**key, "grid": grid}
    fitted = memo_step(out, "surrogate", step_key, reused, partial(_surrogate_fit, judge, budget, limit, progress))
    rows = res.get("samples") or []
    if len(rows) >= HOLDOUT_PARTS:
        held, against = [(_part(r["errors"]), r["metric"]) for r in rows], "the direct Monte Carlo's parts"
    else:
        own = memo_step(out, "surrogate_holdout", step_key, reused, lambda memo: [
            [p.to_json(), m] for p, m in _own_parts(_kept_metric(judge, memo), judge, budget, 1, HOLDOUT_PARTS)])
        held, against = [(_part(e), m) for e, m in own], "held-out parts of its own"
    checked = validate(fitted["model"], budget, judge.chain, held, limit, n_masks=judge.n_masks)
    return {**fitted, "validation": {**checked, "parts": against}}


def _surrogate_fit(judge, budget, limit, progress, memo) -> dict:
    """{"model", "yield"}: the surrogate fitted, calibrated on ``CALIBRATION_PARTS`` parts of its own, and its yield
    against ``limit`` (the lowest PSF metric that meets the spec); each part judged through ``memo``."""
    from doefab.tolerance.surrogate import calibrate, fit_surrogate, surrogate_yield

    metric = _kept_metric(judge, memo)
    model = fit_surrogate(metric, budget, judge.chain, progress, n_masks=judge.n_masks, gap=not judge.fine.doe_is_stop)
    t = time.perf_counter()
    model = calibrate(model, budget, judge.chain, _own_parts(metric, judge, budget, 0, CALIBRATION_PARTS),
                      n_masks=judge.n_masks)
    y = surrogate_yield(model, budget, judge.chain, limit, n_masks=judge.n_masks)
    model["seconds_total"] = round(model["seconds"] + time.perf_counter() - t, 1)
    return {"model": model, "yield": y}


def _kept_metric(judge, memo):
    """``metric(part)``: the part's PSF metric through ``judge``, kept by ``memo`` (``PartMemo``) under the part's
    errors."""
    import json

    def metric(part) -> float:
        name = json.dumps(json_ready(part.to_json()), sort_keys=True, default=str)
        return memo.keep(name, lambda: judge.evaluate(part)["metric"])
    return metric


def _part(errors: dict) -> PartErrors:
    """A part's errors from their JSON (``PartErrors.to_json``, as kept)."""
    return PartErrors(**{k: _tup(v) for k, v in errors.items()})


def _own_parts(metric, judge, budget, role: int, n: int) -> list:
    """``n`` parts of the surrogate's own, drawn from the budget and judged directly (``metric(part)``): ``role`` 0
    calibrates it, 1 validates it. Their streams' spawn keys, (role, i), are never a direct Monte Carlo's, (i,)."""
    from doefab.tolerance.errors import sample_errors

    children = np.random.SeedSequence(SURROGATE_SEED, spawn_key=(role,)).spawn(n)
    parts = (sample_errors(budget, np.random.default_rng(c), seed=int(c.generate_state(1)[0]), n_masks=judge.n_masks)
             for c in children)
    return [(p, metric(p)) for p in parts]


def _tup(v):
    """JSON lists back to the tuples ``PartErrors`` holds."""
    if isinstance(v, list):
        return tuple(_tup(x) for x in v)
    return v


def _figures(out: Path, res: dict) -> None:
    from doefab.tolerance.spec import meets

    nominal = res["nominal"]["psf"]["psf_metric"]
    plots.tornado_plot(out / "tornado.png", res["tornado"], nominal)
    if "sweeps" in res:
        plots.sweep_plots(out / "sweeps.png", res["sweeps"], nominal)
    if "quantization" in res:
        plots.levels_plot(out / "quantization.png", res["quantization"])
    if "samples" in res:
        spec = res["budget"].get("spec", {})
        ok = [meets({"psf_metric": r["metric"]}, spec, res["task"], "psf", res["nominal"]["psf"])
              for r in res["samples"]]
        plots.yield_plot(out / "yield_vs_n.png", ok, f"PSF level: {spec_words(res, 'psf') or 'no limit'}")
        _delivered_figure(out, res)


def _delivered_figure(out: Path, res: dict) -> None:
    """delivered.png: the task's primary delivered metric over the parts, per PSF the network was told."""
    from doefab.reconstruction.metrics import DISPLAY
    from doefab.tolerance.spec import PRIMARY, spec_limits

    task = res["task"]
    if task not in PRIMARY or not res["samples"] or "network" not in res["samples"][0]:
        return
    m = PRIMARY[task]
    values = {lab: [v for v in (r["network"][lab][m] for r in res["samples"]) if math.isfinite(v)]
              for lab in res["samples"][0]["network"]}
    values = {lab: v for lab, v in values.items() if v}
    if not values:
        return
    nominal = res["nominal"].get("network", {}).get("nominal_psf", {})
    name, unit = DISPLAY[task][m]
    limit = next((lim for _, metric, lim, _ in spec_limits(res["budget"].get("spec", {}), task, "network", nominal)
                  if metric == m), None)
    plots.distribution_plot(out / "delivered.png", values, unit, f"delivered {name}", limit,
                            nominal.get(m, float("nan")))


def _markdown(res: dict) -> list[str]:
    reused = res.get("steps_reused") or []
    whole = [r.replace("_", " ") for r in reused if not r.endswith(IN_PART)]
    part = [r[:-len(IN_PART)].replace("_", " ") for r in reused if r.endswith(IN_PART)]
    note = ([" ".join([f"Reused from an earlier run of the same study: {', '.join(whole)} (their run times are "
                       f"that run's)." if whole else "",
                       f"Resumed with the parts the interrupted run judged: {', '.join(part)} (their run times "
                       f"count this run's parts only)." if part else ""]).strip(), ""] if reused else [])
    lead = lead_text(res)
    return [f"# Tolerance study of {res['design']}", "", *([lead, ""] if lead else []), *summary_lines(res), "", *note,
            *body_lines(res)]

