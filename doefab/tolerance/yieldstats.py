"""A study's numbers from its parts: the yield with its Wilson interval, each metric's mean with its t interval
and the parts' spread (``summarize``), and how an interval is printed.

Example: ``wilson(24, 24)`` is the 95 % interval of a yield of 24 parts in 24, about (0.86, 1.0).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["wilson", "interval_text", "mean_ci", "summarize"]


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a proportion k / n (95 % for z = 1.96): honest at 0 and 1, unlike Wald's."""
    if n <= 0:
        return (float("nan"), float("nan"))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    w = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - w), min(1.0, centre + w))


def interval_text(ci, fmt: str = ".3f") -> str:
    """``lo–hi`` of an interval, or a plain statement when it is undefined (fewer than two parts)."""
    lo, hi = (float(x) for x in ci)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "n/a: fewer than two parts"
    return f"{lo:{fmt}}–{hi:{fmt}}"


def mean_ci(values, span: tuple = (-math.inf, math.inf)) -> dict:
    """Mean and 95 % interval of the mean (Student's t with n − 1 degrees of freedom: a study's few parts leave the
    spread itself uncertain, and t's interval is 5.5 % wider than the normal approximation's 1.96 at 24 parts,
    12 % at 12 and 2.2× at 3; nan below two values), and the 5th, 50th and 95th percentiles of the values
    themselves (what one part delivers, not the mean's uncertainty). A value that is not finite (a failed part's
    NaN, an exact reconstruction's infinite PSNR) is left out of all of them and counted in ``n_not_finite``
    beside the ``n`` values they are of. ``span``: the values the metric can take (``spec.SPAN``), where the
    interval is cut (a few parts' t interval of a fraction can reach past 1).

    Example: ``mean_ci([0.4, 0.6, 0.6, 0.8])["ci95"]`` → [0.340…, 0.859…] (t = 3.18 at 3 degrees of freedom)."""
    from scipy.stats import t

    v = np.asarray(values, float)
    finite = np.isfinite(v)
    counts = {"n": int(finite.sum()), "n_not_finite": int(v.size - finite.sum())}  # the values the mean leaves out
    v = v[finite]
    if v.size == 0:
        return {"mean": float("nan"), "ci95": [float("nan")] * 2, "ci95_width": float("nan"), **counts}
    half = float(t.ppf(0.975, len(v) - 1)) * v.std(ddof=1) / math.sqrt(len(v)) if len(v) > 1 else float("nan")
    m = float(v.mean())
    p05, p50, p95 = (float(x) for x in np.percentile(v, [5, 50, 95]))
    lo, hi = max(m - half, span[0]), min(m + half, span[1])
    return {"mean": m, "ci95": [lo, hi], "ci95_width": float(hi - lo),
            "parts_p05_p50_p95": [p05, p50, p95], **counts}  # the spread of what single parts deliver


def summarize(samples: list[dict], spec: dict, task: str, nominal: dict) -> dict:
    """Mean and interval of every metric, and yield (Wilson interval) against ``spec`` at PSF level and, when
    the parts were judged through the network, for each PSF it was given. ``nominal``: the error-free part's
    values ({"psf": {"psf_metric": ...}, "network": {label: metrics}}) for the spec's relative limits."""
    from doefab.tolerance.spec import PSF_METRIC_SPAN, SPAN, meets

    spans = {"metric": PSF_METRIC_SPAN, "worst": PSF_METRIC_SPAN, "l1_to_nominal": (0.0, 2.0)}  # L1 of two PSFs: ≤ 2
    out = {k: mean_ci([s[k] for s in samples], spans[k]) for k in ("metric", "worst", "l1_to_nominal")}
    ok = [meets({"psf_metric": s["metric"]}, spec, task, "psf", nominal.get("psf", {})) for s in samples]
    out["yield"] = {"level": "psf", "value": float(np.mean(ok)) if ok else float("nan"),
                    "ci95": list(wilson(sum(ok), len(ok))), "n": len(ok)}
    if samples and "network" in samples[0]:
        out["network"] = {}
        for label in samples[0]["network"]:
            rows = [s["network"][label] for s in samples]
            good = [meets(r, spec, task, "network", nominal.get("network", {}).get(label, {})) for r in rows]
            span = SPAN[task]
            out["network"][label] = {"metrics": {k: mean_ci([r[k] for r in rows], span.get(k, (-math.inf, math.inf)))
                                                 for k in rows[0]},
                                     "yield": {"value": float(np.mean(good)), "ci95": list(wilson(sum(good), len(good))),
                                               "n": len(good)}}
    return out
