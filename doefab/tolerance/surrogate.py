"""A sensitivity surrogate of the PSF metric: fitted on a few dozen simulated parts, Monte Carlo on it, and
checked against held-out simulated parts.

Each random error of the budget is a scalar parameter x_j of a part (each mask's etch depth and, composed
along the alignment chain, its shift and rotation on the die; the edge bias; the mount's decenter across and
along the split and its rotation; the gap's random part where the lens, not the DOE, is the stop). Errors the budget fixes (roughness,
corner rounding, the sensor's crosstalk) are in the base part B. The surrogate is additive and quadratic:

    m̂(x) = m(B) + Σ_j a_j x_j + b_j x_j²,

with a_j, b_j from the parts B ± h_j e_j (h_j: 2 σ, or the bound of a uniform error) — 2J + 1 simulated parts.
Held-out parts drawn from the budget give its residuals r = m − m̂. Yield is estimated on 20 000 surrogate
parts with residuals resampled from the held-out ones; its interval widens by the held-out residuals' mean
error (1.96 standard errors each way), so a biased surrogate shows in the interval rather than hiding in it.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from doefab.tolerance.errors import PartErrors, budget_value, nominal_gap, sample_errors
from doefab.tolerance.montecarlo import wilson

__all__ = ["parameters", "fit_surrogate", "surrogate_yield"]


def _chain_depth(chain: dict, m: int) -> int:
    """How many plates' overlay errors add up on mask m (its path to the chrome plate in the alignment chain)."""
    plate, depth, seen = m + 1, 0, set()
    while plate != 0 and plate not in seen:
        seen.add(plate)
        depth += 1
        plate = chain.get(plate, 0)
    return max(depth, 1)


def parameters(budget: dict, chain: dict, n_masks: int, gap: bool = False) -> list[tuple[str, float, object]]:
    """[(name, step h, setter(part, x) → part)] of the budget's random errors (zero-σ ones left out); overlay
    steps are 2 σ of the composed shift of each mask (√(plates on its alignment path) · σ). ``gap``: the axial
    gap's random part is a parameter too (only where the lens, not the DOE, is the aperture stop: otherwise the
    gap moves nothing)."""
    g = lambda s, k: budget_value(budget, s, k)  # noqa: E731
    out = []
    depth = math.hypot(g("etch", "systematic_sigma_percent"), g("etch", "random_sigma_percent")) / 100
    for m in range(n_masks if depth > 0 else 0):
        out.append((f"etch depth, mask {m + 1}", 2 * depth, _setter("depth_scale", m, 1.0)))
    shift = g("overlay", "shift_sigma_um") * 1e-6
    for m in range(n_masks if shift > 0 else 0):
        h = 2 * shift * math.sqrt(_chain_depth(chain, m))
        out.append((f"overlay x, mask {m + 1}", h, _setter("overlay", m, None, 0)))
        out.append((f"overlay y, mask {m + 1}", h, _setter("overlay", m, None, 1)))
    rot = g("overlay", "rotation_sigma_urad") * 1e-6
    for m in range(n_masks if rot > 0 else 0):
        out.append((f"mask rotation, mask {m + 1}", 2 * rot * math.sqrt(_chain_depth(chain, m)),
                    _setter("rotation", m, None)))
    if g("lithography", "edge_bias_sigma_um") > 0:
        out.append(("edge bias", 2e-6 * g("lithography", "edge_bias_sigma_um"), _field("edge_bias")))
    dmax = g("mounting", "decenter_max_mm") * 1e-3
    if dmax > 0:
        out.append(("decenter across split", dmax, _pair("mount_shift", 0)))
        out.append(("decenter along split", dmax, _pair("mount_shift", 1)))
    if g("mounting", "rotation_sigma_deg") > 0:
        out.append(("mount rotation", 2 * math.radians(g("mounting", "rotation_sigma_deg")), _field("mount_rotation")))
    if gap and g("mounting", "axial_gap_sigma_mm") > 0:
        g0 = nominal_gap(budget)
        out.append(("axial gap", 2e-3 * g("mounting", "axial_gap_sigma_mm"),
                    lambda part, x: replace(part, axial_gap=max(0.0, g0 + x))))
    return out


def _setter(name, m, base, axis=None):
    def set_(part, x):
        v = list(getattr(part, name))
        if axis is None:
            v[m] = (base if base is not None else 0.0) + x
        else:
            xy = list(v[m])
            xy[axis] = x
            v[m] = tuple(xy)
        return replace(part, **{name: tuple(v)})
    return set_


def _field(name):
    return lambda part, x: replace(part, **{name: x})


def _pair(name, axis):
    def set_(part, x):
        v = list(getattr(part, name))
        v[axis] = x
        return replace(part, **{name: tuple(v)})
    return set_


def base_part(budget: dict) -> PartErrors:
    """The part with the budget's fixed errors only (no random draw)."""
    from doefab.tolerance.errors import sensor_errors

    g = lambda s, k, d=0.0: budget_value(budget, s, k, d)  # noqa: E731
    return replace(PartErrors(), corner_rounding=g("lithography", "corner_rounding_um") * 1e-6,
                   roughness=g("surface", "roughness_rms_nm") * 1e-9,
                   roughness_corr=g("surface", "correlation_length_um", 2.0) * 1e-6, axial_gap=nominal_gap(budget),
                   **sensor_errors(budget))


def features(part: PartErrors, budget: dict, chain: dict, n_masks: int, gap: bool = False) -> np.ndarray:
    """The surrogate's parameters x_j of a sampled part (overlay and mask rotation composed along the chain, as
    the judge applies them)."""
    from doefab.tolerance.judge import compose_overlay

    shifts, rots = compose_overlay(part, chain, n_masks)
    composed = replace(part.for_masks(n_masks), overlay=tuple(shifts), rotation=tuple(rots))
    vals = []
    for name, _, _ in parameters(budget, chain, n_masks, gap):
        if name.startswith("etch depth"):
            vals.append(composed.depth_scale[int(name[-1]) - 1] - 1.0)
        elif name.startswith("overlay"):
            vals.append(composed.overlay[int(name[-1]) - 1][0 if name[8] == "x" else 1])
        elif name.startswith("mask rotation"):
            vals.append(composed.rotation[int(name[-1]) - 1])
        elif name == "edge bias":
            vals.append(composed.edge_bias)
        elif name.startswith("decenter"):
            vals.append(composed.mount_shift[0 if "across" in name else 1])
        elif name == "axial gap":
            vals.append(composed.axial_gap - nominal_gap(budget))
        else:
            vals.append(composed.mount_rotation)
    return np.array(vals)


def fit_surrogate(evaluate, budget: dict, chain: dict, progress: bool = True, *, n_masks: int,
                  gap: bool = False) -> dict:
    """{"base", "names", "h", "a", "b", "parts", "seconds", "gap"}: the surrogate from 2J + 1 simulated parts of
    a design of ``n_masks`` masks; ``evaluate(part) → metric`` judges a part (parameters are set on the base
    part, each alone); ``gap``: as in :func:`parameters`."""
    params = parameters(budget, chain, n_masks, gap)
    base = base_part(budget).for_masks(n_masks)
    t = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=2 * len(params) + 1, desc="surrogate fit", unit="part")
    m0 = evaluate(base)
    if bar is not None:
        bar.update(1)
    a, b = [], []
    for _, h, set_ in params:
        plus, minus = evaluate(set_(base, h)), evaluate(set_(base, -h))
        a.append((plus - minus) / (2 * h))
        b.append((plus + minus - 2 * m0) / (2 * h * h))
        if bar is not None:
            bar.update(2)
            bar.set_postfix(metric=f"{plus:.3f}")
    if bar is not None:
        bar.close()
    return {"base": m0, "names": [p[0] for p in params], "h": [p[1] for p in params], "a": a, "b": b,
            "parts": 2 * len(params) + 1, "seconds": round(time.perf_counter() - t, 1), "gap": bool(gap)}


def predict(model: dict, x: np.ndarray) -> np.ndarray:
    a, b = np.asarray(model["a"]), np.asarray(model["b"])
    return model["base"] + x @ a + (x * x) @ b


def surrogate_yield(model: dict, budget: dict, chain: dict, held_out: list[tuple[PartErrors, float]], meets,
                    draws: int = 20000, seed: int = 12345, *, n_masks: int) -> dict:
    """Yield on ``draws`` surrogate parts (of a design of ``n_masks`` masks) with held-out residuals resampled;
    ``meets(metric) → bool``. The interval: the Wilson interval of the draws, widened by shifting every
    prediction by ±1.96 standard errors of the held-out residuals' mean."""
    gap = bool(model.get("gap", False))
    xs = np.array([features(p, budget, chain, n_masks, gap) for p, _ in held_out])
    resid = np.array([m for _, m in held_out]) - predict(model, xs)
    rng = np.random.default_rng(seed)
    children = np.random.SeedSequence(seed).spawn(draws)
    x = np.array([features(sample_errors(budget, np.random.default_rng(c), n_masks=n_masks), budget, chain, n_masks,
                           gap) for c in children])
    pred = predict(model, x) + rng.choice(resid, size=draws)
    se = resid.std(ddof=1) / math.sqrt(len(resid)) if len(resid) > 1 else float("nan")
    k = int(sum(meets(v) for v in pred))
    lo_shift = int(sum(meets(v) for v in pred - 1.96 * se))
    hi_shift = int(sum(meets(v) for v in pred + 1.96 * se))
    lo = min(wilson(lo_shift, draws)[0], wilson(k, draws)[0])
    hi = max(wilson(hi_shift, draws)[1], wilson(k, draws)[1])
    return {"value": k / draws, "ci95": [lo, hi], "draws": draws,
            "held_out": {"n": len(resid), "rmse": float(np.sqrt(np.mean(resid ** 2))), "bias": float(resid.mean()),
                         "bias_se": float(se), "max_abs": float(np.abs(resid).max())}}
