"""What a part must deliver: per-task specs on the PSF metric and on the delivered quality, and yield.

A budget's ``[spec.<task>]`` table (task: hdr, hyperspectral, depth) holds limits, each key naming the metric,
its unit and the limit's kind:

- ``psf_metric_min``: the design's PSF metric (fraction of the coded light in the task's band);
- absolute delivered limits, e.g. ``psnr_highlight_db_min = 28``, ``sam_rad_max = 0.45``, ``mae_m_max = 0.3``;
- limits relative to the nominal (error-free) part, e.g. ``psnr_highlight_db_loss_max = 1.0`` (at most 1 dB
  below what the nominal part delivers), ``mae_m_increase_max = 0.05``.

Every limit must lie within its metric's span (``SPAN``: a fraction 0–1, PSNR 0–100 dB, SAM 0–π rad...), a
margin within 0 and the span's width; the budget check refuses any other value before any work.

A part meets spec when it meets every limit that applies at the level it was judged on (PSF level: the PSF
metric; network level: the delivered metrics, reconstructed with the nominal PSF and with the part's own).
"""

from __future__ import annotations

import math

from doefab.applications import View, application
from doefab.errors import DoefabError

__all__ = ["DELIVERED", "SPAN", "PSF_METRIC_SPAN", "TASK_OF_DESIGN", "PRIMARY", "delivered_loss", "spec_keys",
           "limit_range", "check_spec", "meets", "relative_kind", "relative_words", "nominal_failures", "limits_text", "spec_limits"]

# views of the application registry's Metric rows (``doefab.applications``, read on every lookup): the delivered
# metrics per task, name → (unit as spec keys spell it, better: "+" higher is better, "-" lower is better), and
# the values each can take (in its unit): the range of an absolute limit; a margin lies in 0 – the width
DELIVERED = View(lambda a: {m.name: (m.unit.lower(), "+" if m.higher_is_better else "-") for m in a.metrics})
SPAN = View(lambda a: {m.name: m.span for m in a.metrics})
PSF_METRIC_SPAN = (0.0, 1.0)  # the PSF metric: a fraction of the coded light
# design task → application, and the delivered metric a task's summary, histogram and "what limits it" are
# ranked by
TASK_OF_DESIGN = View(lambda a: a.name, key=lambda a: a.design_task)
PRIMARY = View(lambda a: a.primary_metric)


def delivered_loss(task: str, delta: dict) -> float:
    """How much worse a change ``delta`` ({metric: new − old}) leaves the task's primary delivered metric
    (positive: worse; dB for PSNR, metres for depth MAE)."""
    m = PRIMARY[task]
    d = float(delta.get(m, float("nan")))
    return -d if DELIVERED[task][m][1] == "+" else d


def _key_parts(task: str) -> dict:
    """{spec key: (metric, kind)} for a task; kind: min, max (absolute), loss (relative, higher is better),
    increase (relative, lower is better)."""
    out = {"psf_metric_min": ("psf_metric", "min"), "psf_metric_loss_max": ("psf_metric", "loss")}
    for name, (unit, better) in DELIVERED[task].items():
        u = f"_{unit}" if unit else ""
        if better == "+":
            out[f"{name}{u}_min"] = (name, "min")
            out[f"{name}{u}_loss_max"] = (name, "loss")
        else:
            out[f"{name}{u}_max"] = (name, "max")
            out[f"{name}{u}_increase_max"] = (name, "increase")
    return out


def spec_keys(task: str) -> list[str]:
    return list(_key_parts(task))


def limit_range(task: str, key: str) -> tuple[float, float, str]:
    """(lo, hi, unit) a spec key of ``task`` may take: its metric's span for an absolute limit, 0 to the span's
    width for a margin (``*_loss_max``, ``*_increase_max``)."""
    metric, kind = _key_parts(task)[key]
    lo, hi = PSF_METRIC_SPAN if metric == "psf_metric" else SPAN[task][metric]
    unit = "" if metric == "psf_metric" else application(task).metric(metric).unit
    return (0.0, hi - lo, unit) if kind in ("loss", "increase") else (lo, hi, unit)


def _range_text(task: str, key: str) -> str:
    lo, hi, unit = limit_range(task, key)
    return f"{lo:g}–{hi:.4g}{f' {unit}' if unit else ''}"


def check_spec(spec: dict, where: str = "[spec]") -> list[str]:
    """Problems of a budget's ``[spec]`` section (per-task tables; every key of a known task, a finite number
    within ``limit_range``)."""
    problems = []
    for task, table in spec.items():
        if task not in DELIVERED:
            problems.append(f"{where}: unknown table spec.{task} (tables: {', '.join(DELIVERED)})")
            continue
        if not isinstance(table, dict):
            problems.append(f"spec.{task} must be a table of limits")
            continue
        keys = _key_parts(task)
        for k, v in table.items():
            if k not in keys:
                problems.append(f"unknown key spec.{task}.{k} (keys: {', '.join(keys)})")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                problems.append(f"spec.{task}.{k} must be a number within {_range_text(task, k)}, got {v!r}")
            elif not limit_range(task, k)[0] <= v <= limit_range(task, k)[1]:
                margin = keys[k][1] in ("loss", "increase")
                what = "a margin below the nominal part" if margin else f"the values {keys[k][0]} takes"
                problems.append(f"spec.{task}.{k} = {v} is outside {_range_text(task, k)} ({what}): give a value "
                                f"within it")
    return problems


def spec_limits(spec: dict, task: str, level: str, nominal: dict) -> list[tuple[str, str, float, str]]:
    """[(key, metric, limit, "≥"/"≤")] that apply at ``level`` ("psf" or "network"), relative limits turned
    absolute against the nominal part's values."""
    out = []
    table = spec.get(task, {})
    for k, (metric, kind) in _key_parts(task).items():
        if k not in table or (metric == "psf_metric") != (level == "psf"):
            continue
        v = float(table[k])
        if kind in ("loss", "increase"):
            if metric not in nominal:
                continue
            base = float(nominal[metric])
            out.append((k, metric, base - v if kind == "loss" else base + v, "≥" if kind == "loss" else "≤"))
        else:
            out.append((k, metric, v, "≥" if kind == "min" else "≤"))
    return out


def relative_kind(task: str, key: str) -> str | None:
    """"loss" or "increase" where the spec key ``key`` of ``task`` sets a limit relative to the error-free part
    (e.g. ``psnr_highlight_db_loss_max``), None for an absolute one.

    Example: ``relative_kind("hdr", "psnr_highlight_db_loss_max")`` → ``"loss"``."""
    kind = _key_parts(task).get(key, (None, None))[1]
    return kind if kind in ("loss", "increase") else None


def relative_words(task: str, spec: dict, key: str, metric: str, nominal: dict) -> str:
    """How a limit relative to the error-free part was set, e.g. " (1.00 dB below the error-free part's 29.35 dB)";
    '' for an absolute one (``spec``: the budget's spec tables, by task)."""
    from doefab.reconstruction.metrics import metric_text

    kind = relative_kind(task, key)
    if kind is None:
        return ""
    way = "below" if kind == "loss" else "above"
    return (f" ({metric_text(task, metric, float(spec[task][key]))} {way} the error-free part's "
            f"{metric_text(task, metric, float(nominal[metric]))})")


def meets(values: dict, spec: dict, task: str, level: str, nominal: dict) -> bool:
    """Whether a part with metric ``values`` meets every limit of ``spec`` that applies at ``level``."""
    for _, metric, limit, op in spec_limits(spec, task, level, nominal):
        v = values.get(metric, float("nan"))
        if not math.isfinite(v) or (v < limit if op == "≥" else v > limit):
            return False
    return True


def nominal_failures(spec: dict, task: str, level: str, nominal: dict) -> list[str]:
    """The limits the nominal (error-free) part already misses: a spec the design cannot meet."""
    return [f"{k}: nominal {nominal[m]:.4g} {'<' if op == '≥' else '>'} {lim:.4g}"
            for k, m, lim, op in spec_limits(spec, task, level, nominal)
            if m in nominal and (nominal[m] < lim if op == "≥" else nominal[m] > lim)]


def limits_text(spec: dict, task: str, level: str, nominal: dict) -> str:
    """The limits as people read them, e.g. "psnr_highlight ≥ 30.7 (nominal − 1 dB)"."""
    lim = spec_limits(spec, task, level, nominal)
    if not lim:
        raise DoefabError(f"the budget's [spec.{task}] sets no limit judged at {level} level")
    return ", ".join(f"{m} {op} {v:.4g}" for _, m, v, op in lim)
