"""The tolerance report's text: its opening paragraph in words (``lead_text``), the summary's details
(``summary_lines``) and the tables after them: grids, tornado, Monte Carlo, surrogate, quantization, sweeps."""

from __future__ import annotations

import math

from doefab.reconstruction.metrics import DISPLAY, metric_text
from doefab.tolerance.montecarlo import interval_text

__all__ = ["body_lines", "lead_text", "summary_lines", "spec_words", "delta_text", "REMEDY"]

# what would remove each error, for the summary
REMEDY = {
    "etch depth (systematic)": "tighter etch-depth control (monitor wafers, an etch-stop layer)",
    "mask overlay": "a better aligner (a stepper holds ≤ 0.2 µm; contact aligners 0.5–2 µm)",
    "mask rotation": "a better aligner",
    "edge bias": "CD control (exposure dose and etch calibrated on the CD ladder)",
    "corner rounding": "a finer mask writer",
    "surface roughness": "a smoother etch",
    "decenter across split": "a tighter die pocket in the holder (holder clearance_mm) or an alignment pin",
    "decenter along split": "a tighter die pocket in the holder (clearance_mm)",
    "mount rotation": "index pins or a tighter pocket (holder clearance_mm), or turning the die to the split",
    "axial gap": "mounting the DOE at the lens's stop",
    "crosstalk, uncalibrated": "calibrating the dual-pixel crosstalk (white-wall captures, the paper's Eq. 30–31)",
    "crosstalk, calibrated": "more rows or frames in the crosstalk calibration",
}
PSF_WORDS = "of its coded light where the task wants it (the PSF metric)"


def _name(task: str, metric: str) -> str:
    return DISPLAY.get(task, {}).get(metric, (metric, ""))[0]


def _interval(task: str, metric: str, ci) -> str:
    """``lo–hi unit`` of a delivered metric's interval (or why there is none)."""
    lo, hi = (float(x) for x in ci)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return interval_text(ci)
    return f"{metric_text(task, metric, lo, unit=False)}–{metric_text(task, metric, hi)}"


def delta_text(task: str, deltas: dict) -> str:
    """Changes of delivered metrics in words with units, e.g. "highlight PSNR -1.2 dB, PSNR -0.3 dB"."""
    return ", ".join(f"{_name(task, k)} {v:+.3g} {_unit(task, k)}".rstrip() for k, v in deltas.items())


def _unit(task: str, metric: str) -> str:
    return DISPLAY.get(task, {}).get(metric, (metric, ""))[1]


def spec_words(res: dict, level: str, label: str = "nominal_psf") -> str | None:
    """The spec's limits at ``level`` in words with units, e.g. "highlight PSNR ≥ 28.90 dB" (None: no limit)."""
    from doefab.tolerance.spec import spec_limits

    task = res["task"]
    nominal = res["nominal"]["psf"] if level == "psf" else res["nominal"].get("network", {}).get(label, {})
    limits = spec_limits(res.get("budget", {}).get("spec", {}), task, level, nominal)
    return ", ".join(f"PSF metric {op} {v:.3f}" if m == "psf_metric" else
                     f"{_name(task, m)} {op} {metric_text(task, m, v)}" for _, m, v, op in limits) or None


def lead_text(res: dict) -> str | None:
    """The report's first paragraph, in plain words with units: what the parts deliver, how many of them meet
    the spec and what limits them most (None without a Monte Carlo)."""
    from doefab.tolerance.spec import PRIMARY

    s = res.get("summary")
    if not s:
        return None
    task, n = res["task"], s["yield"]["n"]
    parts = f"{n} simulated fabricated part{'' if n == 1 else 's'}"
    net, m = s.get("network", {}).get("nominal_psf"), PRIMARY.get(res["task"])
    if net and m in net["metrics"]:
        d, nominal = net["metrics"][m], res["nominal"]["network"]["nominal_psf"].get(m, float("nan"))
        first = (f"This part delivers {metric_text(task, m, d['mean'])} {_name(task, m)}, the mean over {parts} "
                 f"reconstructed by the task's network told the nominal PSF (95 % interval of the mean "
                 f"{_interval(task, m, d['ci95'])}; the error-free part {metric_text(task, m, nominal)}).")
        level, y = "network", net["yield"]
    else:
        d = s["metric"]
        first = (f"This part puts {d['mean']:.3f} {PSF_WORDS}, the mean over {parts} (95 % interval of the mean "
                 f"{interval_text(d['ci95'])}; the error-free part {res['nominal']['psf']['psf_metric']:.3f}).")
        level, y = "psf", s["yield"]
    spec = spec_words(res, level)
    lo, hi = (float(x) for x in y["ci95"])
    second = (f"{100 * y['value']:.0f} % of the parts (95 % Wilson interval {100 * lo:.0f}–{100 * hi:.0f} %) meet "
              f"the spec ({spec})." if spec and math.isfinite(lo) and math.isfinite(hi) else
              f"{100 * y['value']:.0f} % of the parts meet the spec ({spec})." if spec else
              f"The budget's [spec.{task}] sets no limit at this level, so no yield is stated.")
    return " ".join([first, second] + _limit_sentence(res))


def _limit_sentence(res: dict) -> list[str]:
    metric, top = _limits(res)
    if not top:
        return []
    loss, r = top[0]
    what = (f"{metric_text(res['task'], metric, loss)} of {_name(res['task'], metric)}" if metric else
            f"{loss:.3f} of the PSF metric")
    return [f"It is limited most by {r['error']} ({r['value']:.3g} {r['unit']} at the budget's 1σ costs {what}); "
            f"{REMEDY.get(r['error'], r['error'])} would buy the most."]


def summary_lines(res: dict) -> list[str]:
    """The summary's details, a Markdown list: what the part delivers, its yield, what limits it and what would
    buy the most, warnings, the aperture stop."""
    lines = []
    s = res.get("summary")
    task = res["task"]
    if s:
        m = s["metric"]
        lines.append(f"- **PSF metric** (fraction of the coded light in the task's band) {m['mean']:.3f} (95 % "
                     f"interval of the mean {interval_text(m['ci95'])}; nominal {res['nominal']['psf']['psf_metric']:.3f}),"
                     f" {s['yield']['n']} parts.")
        y = s["yield"]
        lines.append(f"- **Yield at PSF level** ({spec_words(res, 'psf') or 'no limit'}): {y['value']:.2f}, 95 % "
                     f"Wilson interval {interval_text(y['ci95'], '.2f')}.")
        for label, v in s.get("network", {}).items():
            ms = ", ".join(f"{_name(task, k)} {metric_text(task, k, d['mean'])} (mean's interval "
                           f"{_interval(task, k, d['ci95'])}"
                           + (f"; parts 5–95 %: {_interval(task, k, d['parts_p05_p50_p95'][::2])}"
                              if "parts_p05_p50_p95" in d and len(res.get("samples", [])) >= 5 else "") + ")"
                           for k, d in v["metrics"].items())
            lines.append(f"- **Delivered, network given the {label.replace('_psf', ' PSF').replace('_', ' ')}**: {ms}; yield "
                         f"({spec_words(res, 'network', label) or 'no limit'}) "
                         f"{v['yield']['value']:.2f} ({interval_text(v['yield']['ci95'], '.2f')}).")
    lines += _limits_lines(res)
    lines += [f"- **Warning:** {w}" for w in res.get("warnings", [])]
    used = res.get("budget", {}).get("defaults_used")
    if used:
        lines.append(f"- Budget keys missing from {res.get('budget_file', 'the budget')}, taken from the default "
                     f"budget: {', '.join(used)}.")
    lines.append(f"- Aperture stop: {res['stop']}.")
    return lines


def _limits(res: dict) -> tuple[str | None, list[tuple[float, dict]]]:
    """(metric, [(loss, tornado row)]) of the three errors that cost the most: the delivered primary metric's loss
    where the tornado judged errors through the network (network told the nominal PSF), else (None, the PSF
    metric's)."""
    from doefab.tolerance.spec import PRIMARY, delivered_loss

    rows = res["tornado"]
    judged = [r for r in rows if "network_delta" in r and "nominal_psf" in r["network_delta"]]
    if judged and res["task"] in PRIMARY:
        losses = [(delivered_loss(res["task"], r["network_delta"]["nominal_psf"]), r) for r in judged]
        return PRIMARY[res["task"]], sorted(((loss, r) for loss, r in losses if math.isfinite(loss) and loss > 0),
                                            key=lambda t: -t[0])[:3]
    return None, [(-r["delta"], r) for r in rows if r["delta"] < 0][:3]


def _limits_lines(res: dict) -> list[str]:
    """"Limited by" and "would buy the most", ranked as ``_limits`` ranks them."""
    metric, top = _limits(res)
    if not top:
        return []
    task, rows = res["task"], res["tornado"]
    if metric is None:
        return ["- **Limited by** (PSF metric) " + "; ".join(
                    f"{r['error']} at {r['value']:.3g} {r['unit']} ({-loss:+.3f})" for loss, r in top) + ".",
                f"- **Would buy the most:** {REMEDY.get(top[0][1]['error'], top[0][1]['error'])} "
                f"(recovers up to {top[0][0]:.3f} of the PSF metric)."]
    judged = sum("network_delta" in r and "nominal_psf" in r["network_delta"] for r in rows)
    unit = _unit(task, metric)
    scope = ("" if judged == len(rows) else
             f"; the {judged} errors that cost the most PSF metric were judged through the network")
    return ["- **Limited by** (delivered " + _name(task, metric) + ", network told the nominal PSF" + scope + ") "
            + "; ".join(f"{r['error']} at {r['value']:.3g} {r['unit']} ({loss:.3g} {unit} worse)" for loss, r in top)
            + ".",
            f"- **Would buy the most:** {REMEDY.get(top[0][1]['error'], top[0][1]['error'])} (recovers up to "
            f"{top[0][0]:.3g} {unit} of {_name(task, metric)}; PSF metric {-top[0][1]['delta']:.3f})."]


def body_lines(res: dict) -> list[str]:
    lines = _grid(res) + _tornado(res)
    if "samples" in res:
        lines += _monte_carlo(res)
    if "surrogate" in res:
        lines += _surrogate(res)
    if "quantization" in res:
        lines += _quantization(res)
    if "sweeps" in res:
        lines += _sweeps(res)
    return lines


def _grid(res: dict) -> list[str]:
    g = res["grid"]
    if g.get("fixed"):
        return ["## Simulation grid", "", f"Every error on the {g['monte_carlo_grid']}× grid (chosen by the user).", ""]
    lines = ["## Simulation grid", "",
             f"Each grid-dependent error alone at one standard deviation of the budget on a {g['block_px']}² block of the design, on "
             f"grids 1×, 2×, 4× against {g['reference_grid']}× (bound on the PSF metric's error: twice the summed "
             f"absolute PSF difference over the metric's pixels; tolerance {g['tolerance']}). The Monte Carlo runs "
             f"on the {g['monte_carlo_grid']}× grid. Errors not listed are exact on any grid (etch depth, decenter, "
             f"gap, crosstalk).", "",
             "| error | budget 1σ | bound 1× | bound 2× | bound 4× | its own effect (8×) | grid used |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, v in g["kinds"].items():
        b = v["bound"]
        lines.append(f"| {name} | {v['value']:.3g} {v['unit']} | {b[1] if 1 in b else b['1']:.2g} | "
                     f"{b[2] if 2 in b else b['2']:.2g} | {b[4] if 4 in b else b['4']:.2g} | {v['effect_bound']:.2g} | "
                     f"{v['grid']}× |")
    return lines + [""]


def _tornado(res: dict) -> list[str]:
    net = res["level"] == "network"
    lines = ["## Each error alone at one standard deviation of the budget", "", "| error | value | grid | PSF metric | change |"
             + (" delivered change, network told the nominal PSF | told the part's measured PSF |" if net else ""),
             "| --- | --- | --- | --- | --- |" + (" --- | --- |" if net else "")]
    for r in res["tornado"]:
        row = f"| {r['error']} | {r['value']:.3g} {r['unit']} | {r['grid']}× | {r['metric']:.4f} | {r['delta']:+.4f} |"
        if net:
            d = r.get("network_delta")
            row += (" " + " | ".join(delta_text(res["task"], d[lab])
                                     for lab in ("nominal_psf", "measured_psf")) + " |" if d
                    else " not judged through the network | |")
        lines.append(row)
    return lines + ["", "![tornado](tornado.png)", ""]


def _monte_carlo(res: dict) -> list[str]:
    s = res["summary"]
    lines = ["## Monte Carlo", "",
             f"{len(res['samples'])} parts (seed {res['seed']}) on the {res['grid']['monte_carlo_grid']}× grid, "
             f"{res['monte_carlo_seconds']} s ({res['parts_per_minute']} parts per minute). PSF metric mean "
             f"{s['metric']['mean']:.4f} (95 % interval of the mean {interval_text(s['metric']['ci95'], '.4f')}); "
             f"yield at PSF level {s['yield']['value']:.3f} (Wilson {interval_text(s['yield']['ci95'])}).", ""]
    for label, v in s.get("network", {}).items():
        lines.append(f"- network given the {label.replace('_psf', ' PSF').replace('_', ' ')}: " + ", ".join(
            f"{_name(res['task'], k)} {metric_text(res['task'], k, d['mean'])} ({_interval(res['task'], k, d['ci95'])})"
            for k, d in v["metrics"].items())
            + f"; yield {v['yield']['value']:.3f} ({interval_text(v['yield']['ci95'])})")
    lines += ["", "| parts | yield | 95 % Wilson interval | width | wall time (s) |", "| --- | --- | --- | --- | --- |"]
    lines += [f"| {c['n']} | {c['yield']:.3f} | {c['yield_ci95'][0]:.3f}–{c['yield_ci95'][1]:.3f} | "
              f"{c['yield_ci95_width']:.3f} | {c['seconds']:.0f} |" for c in res["convergence"]]
    return lines + ["", "![yield against the number of parts](yield_vs_n.png)", ""]


def _surrogate(res: dict) -> list[str]:
    m, y = res["surrogate"]["model"], res["surrogate"]["yield"]
    h = y["held_out"]
    agree = res["surrogate"].get("agrees_with_direct")
    return ["## Surrogate", "",
            f"Additive quadratic sensitivity model of the PSF metric in {len(m['names'])} error parameters, fitted on "
            f"{m['parts']} simulated parts ({m['seconds']} s); checked on {h['n']} held-out simulated parts: RMSE "
            f"{h['rmse']:.4f}, mean residual {h['bias']:+.4f} ± {h['bias_se']:.4f}, largest {h['max_abs']:.4f}. "
            f"Yield on {y['draws']} surrogate parts: {y['value']:.3f}, interval {y['ci95'][0]:.3f}–{y['ci95'][1]:.3f}"
            + ("" if agree is None else f"; {'overlaps' if agree else 'does NOT overlap'} the direct Monte Carlo's")
            + ".", ""]


def _quantization(res: dict) -> list[str]:
    lines = ["## Quantization", "",
             f"| levels | quantized from | PSF metric | worst | L1 to the {res.get('n_levels', 16)}-level PSF |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {r['levels']} | {r.get('source', '')} | {r['metric']:.4f} | {r['worst']:.4f} | "
              f"{r['l1_to_nominal']:.4f} |" for r in res["quantization"]]
    return lines + ["", "![quantization](quantization.png)", ""]


def _sweeps(res: dict) -> list[str]:
    lines = ["## One error at a time", "", "| error | magnitude | grid | PSF metric | worst | L1 to nominal |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name, s in res["sweeps"].items():
        lines += [f"| {name} | {r['magnitude']} {s['unit']} | {s['grid']}× | {r['metric']:.4f} | {r['worst']:.4f} | "
                  f"{r['l1_to_nominal']:.4f} |" for r in s["rows"]]
    return lines + ["", "![sweeps](sweeps.png)", ""]
