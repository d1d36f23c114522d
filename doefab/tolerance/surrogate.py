"""A sensitivity surrogate of the PSF metric: fitted on a few dozen simulated parts, calibrated on parts drawn
from the budget, Monte Carlo on it, and validated on parts it never saw.

Each random error of the budget is a scalar parameter x_j of a part (each mask's etch depth and, composed
along the alignment chain, its shift and rotation on the die; the edge bias; the mount's decenter across and
along the split and its rotation; the gap's random part where the lens, not the DOE, is the stop). Errors the
budget fixes (roughness, corner rounding, the sensor's crosstalk) are in the base part B. The model is additive:

    m̂(x) = m(B) + Σ_j g_j(x_j),

g_j(x) = a_j x + b_j x² through the parts B ± h_j e_j (h_j: 2 σ, or the bound of a uniform error) — 2J + 1
parts. A quadratic through ±2σ misstates a loss that is not quadratic: on the committed grating a mount rotation
of 1σ costs a quarter of what it says (the spots stay in their boxes, then leave them) while the decenter costs
more. So the errors whose loss at ±h is at least a tenth of the largest are judged at ±h/2 and ±3h/2 too, and
g_j is the shape-preserving cubic through their points.

Calibration: parts drawn from the budget and judged directly fit m = α + β m̂ (what the one-at-a-time fit
misses, such as errors that together cost less than their sum) and give the scatter about it. The yield on
20 000 surrogate parts counts α + β m̂ + r over every calibration residual r; its interval is a bootstrap over
the calibration parts. Validation, on other parts judged directly (the direct Monte Carlo's, where the study has
them), pairs each part's surrogate probability of meeting the spec with whether it does: surrogate − direct
yield with a 95 % interval, which a biased surrogate cannot hide.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors, sample_errors
from doefab.tolerance.sources import Param, fixed_fields, surrogate_params

__all__ = ["parameters", "fit_surrogate", "calibrate", "surrogate_yield", "validate", "predict"]


def parameters(budget: dict, chain: dict, n_masks: int, gap: bool = False) -> list[Param]:
    """[Param(name, step h, set, get, uniform)] of the budget's random errors (zero-σ ones left out), from its
    sources of error (``sources.SOURCES``); overlay steps are 2 σ of the composed shift of each mask (√(plates on
    its alignment path) · σ). ``gap``: the axial gap's random part is a parameter too (only where the lens, not
    the DOE, is the aperture stop: otherwise the gap moves nothing)."""
    return surrogate_params(budget, chain, n_masks, gap)


def base_part(budget: dict) -> PartErrors:
    """The part with the budget's fixed errors only (no random draw)."""
    return PartErrors(**fixed_fields(budget))


def features(part: PartErrors, budget: dict, chain: dict, n_masks: int, gap: bool = False) -> np.ndarray:
    """The surrogate's parameters x_j of a sampled part (overlay and mask rotation composed along the chain, as
    the judge applies them)."""
    from doefab.tolerance.judge import compose_overlay

    shifts, rots = compose_overlay(part, chain, n_masks)
    composed = replace(part.for_masks(n_masks), overlay=tuple(shifts), rotation=tuple(rots))
    return np.array([p.get(composed) for p in parameters(budget, chain, n_masks, gap)], float)


def fit_surrogate(evaluate, budget: dict, chain: dict, progress: bool = True, *, n_masks: int,
                  gap: bool = False, refine: float = 0.1) -> dict:
    """{"base", "names", "h", "a", "b", "curves", "parts", "seconds", "gap"}: the surrogate of a design of
    ``n_masks`` masks from simulated parts, each parameter set alone on the base part; ``evaluate(part) → metric``
    judges a part; ``gap``: as in :func:`parameters`. Every parameter is judged at ±h (a_j, b_j); those whose
    loss there is at least ``refine`` × the largest one's also at ±h/2 and, for a normal error, ±3h/2: the curve
    through their points (``curves``: name → {"u": x/h, "metric"}) replaces their quadratic."""
    params = parameters(budget, chain, n_masks, gap)
    base = base_part(budget).for_masks(n_masks)
    t = time.perf_counter()
    bar = _Bar(2 * len(params) + 1, progress)
    m0 = bar.judge(evaluate, base)
    ends = [(bar.judge(evaluate, set_(base, -h)), bar.judge(evaluate, set_(base, h))) for _, h, set_, *_ in params]
    a = [(plus - minus) / (2 * h) for (minus, plus), (_, h, *_) in zip(ends, params)]
    b = [(plus + minus - 2 * m0) / (2 * h * h) for (minus, plus), (_, h, *_) in zip(ends, params)]
    loss = [max(m0 - minus, m0 - plus, 0.0) for minus, plus in ends]
    curves = {}
    for (name, h, set_, _, uniform), (minus, plus), lost in zip(params, ends, loss):
        if lost > 0 and lost >= refine * max(loss):
            more = (-0.5, 0.5) if uniform else (-1.5, -0.5, 0.5, 1.5)  # a uniform error lies within ±h
            bar.more(len(more))
            pts = {-1.0: minus, 0.0: m0, 1.0: plus, **{u: bar.judge(evaluate, set_(base, u * h)) for u in more}}
            curves[name] = {"u": sorted(pts), "metric": [pts[u] for u in sorted(pts)]}
    bar.close()
    return {"base": m0, "names": [p[0] for p in params], "h": [p[1] for p in params], "a": a, "b": b,
            "curves": curves, "parts": bar.n, "seconds": round(time.perf_counter() - t, 1), "gap": bool(gap)}


class _Bar:
    """The fit's progress line (tqdm; none when ``progress`` is off) and its count of judged parts."""

    def __init__(self, total: int, progress: bool):
        self.n, self.tqdm = 0, None
        if progress:
            from tqdm import tqdm

            self.tqdm = tqdm(total=total, desc="surrogate fit", unit="part")

    def judge(self, evaluate, part) -> float:
        m = evaluate(part)
        self.n += 1
        if self.tqdm is not None:
            self.tqdm.update(1)
            self.tqdm.set_postfix(metric=f"{m:.3f}")
        return m

    def more(self, k: int) -> None:
        if self.tqdm is not None:
            self.tqdm.total += k
            self.tqdm.refresh()

    def close(self) -> None:
        if self.tqdm is not None:
            self.tqdm.close()


def predict(model: dict, x: np.ndarray) -> np.ndarray:
    """The sensitivity model's metric m̂ at parameters ``x`` ([..., J]), before calibration: the base part's plus
    each parameter's change alone (its quadratic, or its judged curve where it has one)."""
    x = np.asarray(x, float)
    a, b, h = (np.asarray(model[k], float) for k in ("a", "b", "h"))
    change = a * x + b * x * x
    for j, name in enumerate(model["names"]):
        if name in model.get("curves", {}):
            change[..., j] = _curve(model["curves"][name], x[..., j] / h[j]) - model["base"]
    return model["base"] + change.sum(-1)


def _curve(curve: dict, u: np.ndarray) -> np.ndarray:
    """A parameter's judged curve at ``u`` (its value over its step h): shape-preserving cubic (PCHIP) through
    its points, straight on with the end intervals' slopes beyond them."""
    from scipy.interpolate import PchipInterpolator

    pu, pm = np.asarray(curve["u"], float), np.asarray(curve["metric"], float)
    inside = PchipInterpolator(pu, pm, extrapolate=False)(np.clip(u, pu[0], pu[-1]))
    lo, hi = (pm[1] - pm[0]) / (pu[1] - pu[0]), (pm[-1] - pm[-2]) / (pu[-1] - pu[-2])
    return inside + np.minimum(u - pu[0], 0) * lo + np.maximum(u - pu[-1], 0) * hi


def _judged(model: dict, budget: dict, chain: dict, parts, n_masks: int) -> tuple[np.ndarray, np.ndarray]:
    """(m̂, m) of directly judged ``parts`` [(PartErrors, metric)]."""
    gap = bool(model.get("gap", False))
    xs = np.array([features(p, budget, chain, n_masks, gap) for p, _ in parts]).reshape(len(parts), -1)
    return predict(model, xs), np.array([float(m) for _, m in parts])


def _line(pred: np.ndarray, metric: np.ndarray) -> tuple[float, float]:
    """α, β of m ≈ α + β m̂ by least squares (β = 1, a shift alone, where the predictions do not vary)."""
    v = float(np.var(pred))
    beta = float(np.mean((pred - pred.mean()) * (metric - metric.mean())) / v) if v > 1e-12 else 1.0
    return float(metric.mean() - beta * pred.mean()), beta


def calibrate(model: dict, budget: dict, chain: dict, parts: list[tuple[PartErrors, float]], *, n_masks: int) -> dict:
    """The model with its calibration on ``parts`` [(PartErrors, metric)]: parts drawn from the budget and judged
    directly (never those it is validated on). The line m = α + β m̂ through them by least squares carries what
    the one-at-a-time fit misses (errors that together cost less than the sum of their losses alone), and its
    residuals the scatter about it."""
    if len(parts) < 3:
        raise DoefabError(f"the surrogate's calibration needs at least 3 directly judged parts, got {len(parts)}: "
                          f"give 16 (CALIBRATION_PARTS)")
    pred, metric = _judged(model, budget, chain, parts, n_masks)
    alpha, beta = _line(pred, metric)
    resid = metric - (alpha + beta * pred)
    return {**model, "calibration": {"n": len(parts), "alpha": alpha, "beta": beta, "predicted": pred.tolist(),
                                     "metric": metric.tolist(), "rmse": float(np.sqrt(np.mean(resid ** 2))),
                                     "rmse_uncalibrated": float(np.sqrt(np.mean((metric - pred) ** 2)))}}


def _pass_rate(pred: np.ndarray, cal_pred: np.ndarray, cal_metric: np.ndarray, limit: float) -> np.ndarray:
    """Per prediction m̂, the share of calibration residuals r with α + β m̂ + r ≥ ``limit`` (α, β, r from the
    calibration parts): the probability that a part so predicted meets the limit."""
    alpha, beta = _line(cal_pred, cal_metric)
    resid = np.sort(cal_metric - (alpha + beta * cal_pred))
    need = limit - (alpha + beta * pred)  # the residual each part needs
    return 1.0 - np.searchsorted(resid, need, side="left") / len(resid)


def _calibration_of(model: dict) -> tuple[np.ndarray, np.ndarray]:
    cal = model.get("calibration")
    if not cal:
        raise DoefabError("the surrogate has no calibration: pass it through calibrate(model, budget, chain, parts, "
                          "n_masks=...) with 16 directly judged parts first")
    return np.asarray(cal["predicted"], float), np.asarray(cal["metric"], float)


def surrogate_yield(model: dict, budget: dict, chain: dict, limit: float, draws: int = 20000, seed: int = 12345,
                    resamples: int = 400, *, n_masks: int) -> dict:
    """Yield on ``draws`` surrogate parts of a design of ``n_masks`` masks: each part's calibrated metric
    α + β m̂ with every calibration residual added, against ``limit`` (the lowest PSF metric that meets the spec).
    Its 95 % interval: the 2.5–97.5 percentiles over ``resamples`` bootstrap resamples of the calibration parts
    (line and residuals fitted again) and of the draws."""
    cal_pred, cal_metric = _calibration_of(model)
    gap = bool(model.get("gap", False))
    x = np.array([features(sample_errors(budget, np.random.default_rng(c), n_masks=n_masks), budget, chain, n_masks,
                           gap) for c in np.random.SeedSequence(seed).spawn(draws)]).reshape(draws, -1)
    pred = predict(model, x)
    value = float(_pass_rate(pred, cal_pred, cal_metric, limit).mean())
    rng, n = np.random.default_rng(seed), len(cal_pred)
    boot = []
    for _ in range(resamples):
        i, k = rng.integers(0, n, n), rng.integers(0, draws, draws)
        boot.append(_pass_rate(pred[k], cal_pred[i], cal_metric[i], limit).mean())
    lo, hi = np.percentile(boot, [2.5, 97.5]) if boot else (value, value)
    return {"value": value, "ci95": [float(lo), float(hi)], "draws": draws, "limit": float(limit),
            "resamples": resamples}


def validate(model: dict, budget: dict, chain: dict, parts: list[tuple[PartErrors, float]], limit: float, *,
             n_masks: int) -> dict:
    """The calibrated surrogate against ``parts`` it never saw [(PartErrors, metric)], judged directly, paired
    part by part: its probability that each part meets ``limit`` minus whether the part does (mean: surrogate −
    direct yield on these parts), and its metric minus the judged one, each with a 95 % interval (Student t over
    the parts). ``consistent``: the yield's interval holds zero."""
    from scipy.stats import t as student

    if len(parts) < 2:
        raise DoefabError(f"validating the surrogate needs at least 2 directly judged parts it never saw, got "
                          f"{len(parts)}: give 16 (HOLDOUT_PARTS)")
    cal_pred, cal_metric = _calibration_of(model)
    alpha, beta = _line(cal_pred, cal_metric)
    pred, metric = _judged(model, budget, chain, parts, n_masks)
    p = _pass_rate(pred, cal_pred, cal_metric, limit)
    ok = metric >= limit
    q = float(student.ppf(0.975, len(parts) - 1))

    def paired(d):
        half = q * float(np.std(d, ddof=1)) / math.sqrt(len(d))
        return float(np.mean(d)), [float(np.mean(d) - half), float(np.mean(d) + half)]

    dy, dy_ci = paired(p - ok)
    dm, dm_ci = paired(alpha + beta * pred - metric)
    return {"n": len(parts), "yield_surrogate": float(p.mean()), "yield_direct": float(ok.mean()),
            "yield_difference": dy, "yield_difference_ci95": dy_ci, "metric_difference": dm,
            "metric_difference_ci95": dm_ci, "rmse": float(np.sqrt(np.mean((alpha + beta * pred - metric) ** 2))),
            "rmse_uncalibrated": float(np.sqrt(np.mean((pred - metric) ** 2))),
            "consistent": bool(dy_ci[0] <= 0.0 <= dy_ci[1])}
