"""Tolerance studies: one-at-a-time sweeps, a tornado ranking (at PSF level or in delivered quality through the
network), and a quantization study. The Monte Carlo lives in ``montecarlo``, the grid each error needs in
``grid``, the sensitivity surrogate in ``surrogate``.

Judges are built once per (design, grid) per process; workers rebuild them from the design folder.
"""

from __future__ import annotations

import os
from contextlib import ExitStack

import numpy as np

from doefab.tolerance.errors import PartErrors
from doefab.tolerance.kinds import KINDS, kind

__all__ = ["judge_for", "network_judge_for", "evaluate_part", "network_changes", "sweep", "tornado",
           "quantization_study", "continuous_height", "sweep_names", "compute_now"]

_JUDGES: dict = {}
_NET_JUDGES: dict = {}


def judge_for(design_dir, supersample: int = 1):
    """The ``PSFJudge`` of a design folder on a grid (one per process and default device)."""
    from doefab._devices import resolve_device

    key = (str(design_dir), int(supersample), str(resolve_device(None)))
    if key not in _JUDGES:
        import torch

        from doefab.tolerance.judge import PSFJudge

        torch.set_num_threads(1 if os.environ.get("DOEFAB_WORKER") else max(1, torch.get_num_threads()))
        _JUDGES[key] = PSFJudge(design_dir, supersample)
    return _JUDGES[key]


def network_judge_for(design_dir, supersample: int = 1, weights_dir=None, networks=True):
    """The ``NetworkJudge`` of a design folder (its task's proposed network; one per process) on the scenes
    ``networks`` asks for (``netjudge.judge_settings``: True, the defaults)."""
    from doefab.tolerance.netjudge import NetworkJudge, judge_settings

    judge = judge_for(design_dir, supersample)
    settings = judge_settings(networks)
    key = (str(design_dir), int(supersample), str(weights_dir), str(judge.device), str(sorted(settings.items())))
    if key not in _NET_JUDGES:
        _NET_JUDGES[key] = NetworkJudge(judge, weights_dir=weights_dir, **settings)
    return _NET_JUDGES[key]


def evaluate_part(design_dir: str, supersample: int, errors: dict, networks: bool = False,
                  weights_dir=None) -> dict:
    """PSF metrics of a part given as ``PartErrors`` fields (and, with ``networks``, its delivered quality: the
    means over the scenes under "network", each scene's values under "network_scenes")."""
    err = PartErrors(**errors)
    # the network's PSF pair first: the PSF metric's coded PSF is its crop (``PSFJudge.reuse``; for depth, of the
    # rendering PSFs at the network's planes: ``NetworkJudge.rendered_pair``)
    net = network_judge_for(design_dir, supersample, weights_dir, networks).scenes(err) if networks else None
    res = judge_for(design_dir, supersample).evaluate(err)
    if networks:
        res["network"], res["network_scenes"] = network_judge_for(design_dir, supersample, weights_dir,
                                                                  networks).means(net), net
    return res


def sweep_names() -> list[str]:
    """Every error kind with a sweep, in the order reports list them."""
    return [k.name for k in KINDS if k.sweep]


def sweep(design_dir, grids: dict | None = None, names=None, progress: bool = True, keep=None) -> dict:
    """Each PSF metric against each error's magnitude (one error at a time), each kind on its grid
    (``grids[name]``, default 1). ``keep(name, compute)``: what judges each magnitude (default: ``compute()``;
    ``partmemo.PartMemo.keep`` keeps each for a resumed study)."""
    keep = keep or compute_now
    grids = grids or {}
    nominal = {}
    out = {"sweeps": {}}
    items = [kind(n) for n in (names or sweep_names())]
    bar = _bar(sum(len(k.sweep) for k in items), "sweeps", progress)
    for k in items:
        s = int(grids.get(k.name, 1))
        judge = judge_for(design_dir, s)
        nominal.setdefault(s, judge.score(judge.nominal))
        rows = []
        for m in k.sweep:
            r = keep(f"{k.name} at {m!r} on grid {s}", lambda: judge.evaluate(k.build(m * k.si, judge.n_masks)))
            rows.append({"magnitude": m, **r})
            if bar is not None:
                bar.update(1)
                bar.set_postfix(error=k.name[:18], metric=f"{r['metric']:.3f}")
        out["sweeps"][k.name] = {"unit": k.unit, "grid": s, "rows": rows}
    if bar is not None:
        bar.close()
    out["nominal"] = nominal.get(1) or next(iter(nominal.values()))
    return out


def tornado(design_dir, budget: dict, grids: dict | None = None, networks: bool = False, weights_dir=None,
            progress: bool = True, network_top: int | None = None, evaluate=None) -> list[dict]:
    """Each error alone at one standard deviation of the budget, largest change first: the PSF metric, and with
    ``networks`` the delivered metrics (reconstructed with the nominal PSF and with the part's own) — for every
    error, or for the ``network_top`` largest at PSF level. ``evaluate``: what judges a part (default
    ``evaluate_part``; ``partmemo.PartMemo`` keeps each judged part for a resumed study)."""
    evaluate = evaluate or evaluate_part
    grids = grids or {}
    present = [k for k in KINDS if k.from_budget(budget) != 0.0]
    rest = []  # the errors judged at PSF level only
    if networks and network_top is not None:
        nj = network_judge_for(design_dir, 1, weights_dir, networks)
        kernel = nj.rec.pair.coded.shape[-1]  # the network's
        with ExitStack() as stack:  # the PSF pass computes the coded halves the network pass takes up, where it
            # takes them from the design's planes (depth renders on finer planes: nothing to take up there)
            for s in {int(grids.get(k.name, 1)) for k in present} if not nj.renders_elsewhere else ():
                stack.enter_context(judge_for(design_dir, s).computing_at(kernel))
            psf = tornado(design_dir, budget, grids, False, progress=progress, evaluate=evaluate)
        top = {r["error"] for r in psf[:network_top]}
        rest = [r for r in psf if r["error"] not in top]
        present = [k for k in present if k.name in top]
    return sorted(tornado_rows(design_dir, budget, present, grids, networks, weights_dir, progress, evaluate) + rest,
                  key=lambda r: -abs(r["delta"]))


def tornado_rows(design_dir, budget, present, grids, networks, weights_dir, progress, evaluate=None) -> list[dict]:
    """The tornado's rows for the error kinds ``present`` (unsorted), each part judged by ``evaluate`` (default
    ``evaluate_part``)."""
    evaluate = evaluate or evaluate_part
    bar = _bar(len(present), "tornado" + (" (networks)" if networks else ""), progress)
    base = {}
    rows = []
    for k in present:
        s = int(grids.get(k.name, 1))
        j = judge_for(design_dir, s)
        if s not in base:
            base[s] = dict(evaluate(str(design_dir), s, PartErrors().to_json(), networks, weights_dir))
            base[s]["metric"] = j.score(j.nominal)["metric"]
        r = evaluate(str(design_dir), s, k.budget_part(budget, j.n_masks).to_json(), networks, weights_dir)
        b = base[s] if k.base_from_budget is None else evaluate(  # a spread about a nominal value: from it
            str(design_dir), s, k.base_part(budget).to_json(), networks, weights_dir)
        row = {"error": k.name, "value": k.from_budget(budget) / k.si, "unit": k.unit, "grid": s,
               "metric": r["metric"], "delta": r["metric"] - b["metric"]}
        if networks:
            row["network"] = r["network"]
            row["network_delta"], row["network_delta_scenes"] = network_changes(r, b)
        rows.append(row)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(error=k.name[:18], metric=f"{r['metric']:.3f}")
    if bar is not None:
        bar.close()
    return rows


def network_changes(part: dict, base: dict) -> tuple[dict, dict]:
    """(change of the means, change on each scene) of one network-judged part against another judged on the same
    scenes: {label: {metric: part − base}} and {label: {metric: [part − base per scene]}}, from each one's
    "network" means and "network_scenes" values (``evaluate_part``, ``quantization_study``), in the metrics' units.

    Example: ``network_changes({"network": {"nominal_psf": {"mae": 0.3}}, "network_scenes": {"nominal_psf": {"mae":
    [0.2, 0.4]}}}, {"network": {"nominal_psf": {"mae": 0.25}}, "network_scenes": {"nominal_psf": {"mae": [0.2,
    0.3]}}})`` → ``({"nominal_psf": {"mae": 0.05}}, {"nominal_psf": {"mae": [0.0, 0.1]}})`` (metres, to rounding)."""
    means = {lab: {m: v - base["network"][lab][m] for m, v in vals.items()} for lab, vals in part["network"].items()}
    scenes = {lab: {m: [p - q for p, q in zip(v, base["network_scenes"][lab][m])] for m, v in vals.items()}
              for lab, vals in part["network_scenes"].items()}
    return means, scenes


def compute_now(name: str, compute):
    """``compute()``: a step's part judged where nothing keeps it (``partmemo.PartMemo.keep``'s signature), the
    default ``keep`` of the studies that take one. Example: ``compute_now("levels 8", lambda: 8) == 8``."""
    return compute()


def _bar(total, desc, progress, unit="part"):
    """A progress line (tqdm: what runs, k/n done, elapsed and time left), None when ``progress`` is off."""
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit)


def quantization_study(design_dir, levels=None, supersample: int = 1, networks: bool = False, weights_dir=None,
                       progress: bool = True, keep=None) -> list[dict]:
    """The same design at continuous (None) and N-level quantization, on the PSF metric (and, with
    ``networks``, through the network given the nominal and the quantized design's PSF). ``levels``: default
    continuous, the design's L and every fab level count below it. Each row says what it was quantized from: the
    continuous design when the folder keeps it (``height.npy`` or radial knots), else the design's L-level map
    re-quantized (fewer levels from L are not what a coarser design would be). ``progress``: a progress line
    per level count judged. ``keep(name, compute)``: what judges each level count (default: ``compute()``;
    ``partmemo.PartMemo.keep`` keeps each row for a resumed study)."""
    from doefab.fabrication.process import LEVEL_CHOICES

    keep = keep or compute_now
    judge = judge_for(design_dir, supersample)
    d = judge.design
    if levels is None:
        levels = (None, *sorted((n for n in LEVEL_CHOICES if n <= d.n_levels), reverse=True))
    height = continuous_height(d)
    bar = _bar(len(levels), "quantization study" + (" (networks)" if networks else ""), progress, unit="level count")
    rows = []
    for n in levels:
        if bar is not None:
            bar.set_postfix(levels="continuous" if n is None else n)
        rows.append(keep(f"levels {n}", lambda: _quantized_row(design_dir, judge, height, n, supersample, networks,
                                                               weights_dir)))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return rows


def _quantized_row(design_dir, judge, height, n, supersample, networks, weights_dir) -> dict:
    """One row of the quantization study: the design quantized to ``n`` levels (None: continuous)."""
    from doefab.fabrication.levels import quantize_levels

    d = judge.design
    mapped = f"the {d.n_levels}-level map"
    if n is None and height is None:
        return {"levels": "continuous", "metric": None, "worst": None,  # no value: JSON's null, not NaN
                "l1_to_nominal": None, "source": f"n/a: the folder keeps only {mapped}"}
    h2pi = d.camera.material.height_2pi(d.camera.design_wavelength)
    if n is None:
        h = np.mod(height, h2pi)
    else:
        lv = quantize_levels(d.height if height is None else height, d.camera, n)
        h = lv.astype(np.float64) * h2pi / n
    if supersample > 1:
        h = np.kron(h, np.ones((supersample, supersample)))
    nj = network_judge_for(design_dir, supersample, weights_dir, networks) if networks else None
    net = nj.scenes(PartErrors(), height=h) if nj else None  # first: the PSF metric's coded PSF is a crop of its pair
    source = "the continuous design" if height is not None else f"{mapped}, re-quantized"
    row = {"levels": "continuous" if n is None else n, "source": "the continuous design" if n is None
           else (source if n != d.n_levels or height is not None else f"the committed {d.n_levels}-level map"),
           **judge.score(judge.psf_from_height(h))}
    if networks:
        row["network"], row["network_scenes"] = nj.means(net), net
    return row


def continuous_height(design):
    """The design's continuous (unquantized) heights in metres, or None when the folder keeps only its level map:
    from ``height.npy``, or rebuilt from a radial design's knots (``extra.radial_knots_waves``)."""
    import torch

    from doefab.design.optimize import coded_mask, plain_level
    from doefab.design.parameterization import RadialParam, theta_to_height
    from doefab.fabrication.levels import level_step, levels_to_height

    d = design
    if not np.allclose(d.height, levels_to_height(d.levels, d.camera, d.n_levels), rtol=0, atol=1e-12):
        return d.height
    knots = d.extra.get("radial_knots_waves")
    if not knots:
        return None
    with torch.no_grad():
        h = theta_to_height(RadialParam(d.camera, len(knots)).waves(torch.tensor(knots, dtype=torch.float64)),
                            d.camera).numpy()
    mask = coded_mask(d.camera).numpy() > 0
    return np.where(mask, h, plain_level(d.n_levels) * level_step(d.camera, d.n_levels))

