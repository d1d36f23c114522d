"""The tolerance report's text: its opening paragraph in words (``lead_text``), the summary's details
(``summary_lines``) and the tables after them: grids, tornado, Monte Carlo, surrogate, quantization, sweeps."""

from __future__ import annotations

import math

from doefab.reconstruction.metrics import DISPLAY, metric_text
from doefab.tolerance.kinds import KINDS
from doefab.tolerance.yieldstats import interval_text

__all__ = ["body_lines", "lead_text", "summary_lines", "spec_words", "delta_text", "noise_of", "NOISE_NOTE", "REMEDY"]

# what would remove each error, for the summary: each kind's own (``kinds.KINDS``)
REMEDY = {k.name: k.remedy for k in KINDS}
PSF_WORDS = "of its coded light where the task wants it (the PSF metric)"


def _name(task: str, metric: str) -> str:
    return DISPLAY.get(task, {}).get(metric, (metric, ""))[0]


def _interval(task: str, metric: str, ci) -> str:
    """``lo–hi unit`` of a delivered metric's interval (or why there is none)."""
    lo, hi = (float(x) for x in ci)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return interval_text(ci)
    return f"{metric_text(task, metric, lo, unit=False)}–{metric_text(task, metric, hi)}"


def delta_text(task: str, deltas: dict, ci: dict | None = None, names: bool = True) -> str:
    """Changes of delivered metrics in words with units, e.g. "highlight PSNR -1.2 dB, PSNR -0.3 dB"; with ``ci``
    ({metric: half-width of the change's 95 % interval}, ``delivered.change_noise``) "PSNR -0.3 ± 0.41 dB";
    ``names`` off: without the metrics' names ("-0.3 ± 0.41 dB")."""
    ci = ci or {}

    def one(k, v):
        if math.isnan(v):
            return "—"
        return f"{v:+.3g}{'' if ci.get(k) is None else f' ± {ci[k]:.2g}'} {_unit(task, k)}".rstrip()

    return ", ".join(f"{_name(task, k)} {one(k, v)}" if names else one(k, v) for k, v in deltas.items())


def noise_of(row: dict, metric: str, label: str = "nominal_psf") -> float:
    """Half-width of the 95 % interval of a tornado row's delivered change over the judge's scenes
    (``delivered.change_noise``); 0 where the row holds none."""
    v = row.get("network_delta_ci95", {}).get(label, {}).get(metric)
    return 0.0 if v is None else float(v)


NOISE_NOTE = ("± : the 95 % interval of a delivered change over the judge's scenes (each scene's change paired, "
              "Student's t); a change inside it is not resolved by these scenes, and a tornado loss inside it ranks "
              "nothing.")


def _unit(task: str, metric: str) -> str:
    return DISPLAY.get(task, {}).get(metric, (metric, ""))[1]


def signed_change(x: float, digits: int = 4) -> str:
    """A change with its sign, a change that rounds to zero as +0 (no "-0.0000").

    Example: ``signed_change(-4e-6)`` → ``"+0.0000"``; ``signed_change(-0.0123)`` → ``"-0.0123"``."""
    return f"{x if round(x, digits) != 0 else 0.0:+.{digits}f}"


def spec_words(res: dict, level: str, label: str = "nominal_psf") -> str | None:
    """The spec's limits at ``level`` in words with units, e.g. "highlight PSNR ≥ 28.90 dB" (None: no limit)."""
    from doefab.tolerance.spec import relative_words, spec_limits

    task = res["task"]
    nominal = res["nominal"]["psf"] if level == "psf" else res["nominal"].get("network", {}).get(label, {})
    table = res.get("budget", {}).get("spec", {})
    limits = spec_limits(table, task, level, nominal)
    name = {"psf_metric": "PSF metric"}
    return ", ".join(f"{name.get(m) or _name(task, m)} {op} {metric_text(task, m, v)}"
                     + relative_words(task, table, k, m, nominal) for k, m, v, op in limits) or None


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
        two = s.get("delivered", {}).get("nominal_psf")  # intervals over parts and scenes, where judged per scene
        first = (f"This part delivers {metric_text(task, m, d['mean'])} {_name(task, m)}, the mean over {parts} "
                 f"reconstructed by the task's network told the nominal PSF (95 % interval of the mean"
                 f"{' over parts and scenes' if two else ''} {_interval(task, m, two['mean_ci95'] if two else d['ci95'])}"
                 f"; the error-free part {metric_text(task, m, nominal)}).")
        level, y = "network", ({"value": two["yield"], "ci95": two["yield_ci95"], "name": "interval over parts and "
                                "scenes"} if two else net["yield"])
    else:
        d = s["metric"]
        first = (f"This part puts {d['mean']:.3f} {PSF_WORDS}, the mean over {parts} (95 % interval of the mean "
                 f"{interval_text(d['ci95'])}; the error-free part {res['nominal']['psf']['psf_metric']:.3f}).")
        level, y = "psf", s["yield"]
    spec = spec_words(res, level)
    lo, hi = (float(x) for x in y["ci95"])
    second = (f"{100 * y['value']:.0f} % of the parts (95 % {y.get('name', 'Wilson interval')} {100 * lo:.0f}–"
              f"{100 * hi:.0f} %) meet "
              f"the spec ({spec})." if spec and math.isfinite(lo) and math.isfinite(hi) else
              f"{100 * y['value']:.0f} % of the parts meet the spec ({spec})." if spec else
              f"The budget's [spec.{task}] sets no limit at this level, so no yield is stated.")
    return " ".join([first, second] + _limit_sentence(res))


def _limit_sentence(res: dict) -> list[str]:
    metric, top = _limits(res)
    if not top:
        return []
    loss, r = top[0]
    task, noise = res["task"], noise_of(r, metric) if metric else 0.0
    what = (f"{metric_text(task, metric, loss)} of {_name(task, metric)}"
            + (f", ± {metric_text(task, metric, noise)} over the judge's scenes" if noise else "") if metric else
            f"{loss:.3f} of the PSF metric" + ("; no error judged through the network lowered what the part delivers "
                                               "by more than the judge's scene noise" if _unresolved(res) else ""))
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
            ms = ", ".join(f"{_name(task, k)} {metric_text(task, k, d['mean'])} (mean's interval over parts "
                           f"{_interval(task, k, d['ci95'])}"
                           + (f"; parts 5–95 %: {_interval(task, k, d['parts_p05_p50_p95'][::2])}"
                              if "parts_p05_p50_p95" in d and len(res.get("samples", [])) >= 5 else "") + ")"
                           for k, d in v["metrics"].items())
            lines.append(f"- **Delivered, network given the {label.replace('_psf', ' PSF').replace('_', ' ')}**: {ms}; yield "
                         f"({spec_words(res, 'network', label) or 'no limit'}) "
                         f"{v['yield']['value']:.2f} (Wilson interval over parts only "
                         f"{interval_text(v['yield']['ci95'], '.2f')}).")
    lines += _delivered_lines(res) + _limits_lines(res)
    lines += [f"- **Warning:** {w}" for w in res.get("warnings", [])]
    used = res.get("budget", {}).get("defaults_used")
    if used:
        lines.append(f"- Budget keys missing from {res.get('budget_file', 'the budget')}, taken from the default "
                     f"budget: {', '.join(used)}.")
    lines.append(f"- Aperture stop: {res['stop']}.")
    return lines


def _delivered_lines(res: dict) -> list[str]:
    """The delivered-quality yield with its interval over parts and scenes, and the scene noise on a part's value
    against the part-to-part spread (``tolerance.delivered``), network told the nominal PSF."""
    d = res.get("summary", {}).get("delivered", {}).get("nominal_psf")
    if not d:
        return []
    task, m, c = res["task"], d["metric"], d["components"]
    judge = res.get("network_judge", {})
    n = judge.get("images", c["scenes"])
    where = (f"{n} {judge.get('split', '')} scene{'' if n == 1 else 's'} of {judge.get('size', '?')}² px per "
             f"part".replace("  ", " ")
             + (f", {c['scenes']} of which define it" if c["scenes"] != n else ""))
    if not math.isfinite(c["part_sd"]):
        noise = f"scene noise not measured (needs two parts and two scenes; {where})"
    else:
        p = c.get("parts_differ_p", 0.0)
        verdict = ("NOT below it: the parts do not differ measurably" if not c["scenes_needed"] else
                   f"the spread is not resolved by these scenes (F test of the parts p = {p:.2f}): judge each part on "
                   f"more scenes" if p > 0.05 else
                   "below it (point estimates)" if c["part_noise_sd"] < c["part_sd"] else
                   f"NOT below it: judge each part on at least {c['scenes_needed']} scenes (a point estimate)")
        noise = (f"scene noise on a part's {_name(task, m)} {metric_text(task, m, c['part_noise_sd'])} ({where}) "
                 f"against a part-to-part spread of {metric_text(task, m, c['part_sd'])}: {verdict}; the scene set's "
                 f"offset common to every part {metric_text(task, m, c['common_noise_sd'])}")
    y = d["yield"]
    yield_text = ("no limit at network level" if y is None else
                  f"{y:.2f}, 95 % interval {interval_text(d['yield_ci95'], '.2f')} over parts and scenes (two-level "
                  f"bootstrap, {d['draws']} draws, joined with the parts' Wilson interval "
                  f"{interval_text(d['wilson_ci95'], '.2f')})")
    return [f"- **Delivered-quality yield** ({spec_words(res, 'network') or 'no limit'}; network told the nominal "
            f"PSF): {yield_text}; mean {_name(task, m)} {metric_text(task, m, d['mean'])} "
            f"({_interval(task, m, d['mean_ci95'])}); {noise}."]


def _limits(res: dict) -> tuple[str | None, list[tuple[float, dict]]]:
    """(metric, [(loss, tornado row)]) of the three errors that cost the most: the delivered primary metric's loss
    where the tornado judged errors through the network (network told the nominal PSF) and one of them costs
    more than its scene noise (``noise_of``), else (None, the PSF metric's)."""
    from doefab.tolerance.spec import PRIMARY, delivered_loss

    rows = res["tornado"]
    judged = [r for r in rows if "network_delta" in r and "nominal_psf" in r["network_delta"]]
    if judged and res["task"] in PRIMARY:
        m = PRIMARY[res["task"]]
        losses = [(delivered_loss(res["task"], r["network_delta"]["nominal_psf"]), r) for r in judged]
        # a loss counts where the judge's scenes resolve it (beyond its 95 % scene noise; rows without one: > 0)
        top = sorted(((loss, r) for loss, r in losses if math.isfinite(loss) and loss > noise_of(r, m)),
                     key=lambda t: -t[0])[:3]
        if top:
            return m, top
    return None, [(-r["delta"], r) for r in rows if r["delta"] < 0][:3]


def _unresolved(res: dict) -> bool:
    """Whether the tornado judged errors through the network, and some lowered the delivered primary metric but none
    by more than its scene noise (so the PSF metric ranks them)."""
    from doefab.tolerance.spec import PRIMARY, delivered_loss

    m = PRIMARY.get(res["task"])
    losses = [delivered_loss(res["task"], r["network_delta"]["nominal_psf"]) for r in res["tornado"]
              if "nominal_psf" in r.get("network_delta", {})] if m else []
    return any(math.isfinite(x) and x > 0 for x in losses) and _limits(res)[0] is None


def _limits_lines(res: dict) -> list[str]:
    """"Limited by" and "would buy the most", ranked as ``_limits`` ranks them."""
    from doefab.tolerance.spec import PRIMARY

    metric, top = _limits(res)
    if not top:
        return []
    task, rows = res["task"], res["tornado"]
    judged = sum("network_delta" in r and "nominal_psf" in r["network_delta"] for r in rows)
    if metric is None:
        none = (f"; no error of the {judged} judged through the network lowered the delivered "
                f"{_name(task, PRIMARY.get(task, ''))} "
                + ("by more than the scene noise of the judge's scenes (95 %)" if _unresolved(res) else
                   "on the judge's scenes") if judged and task in PRIMARY else "")
        return [f"- **Limited by** (PSF metric{none}) " + "; ".join(
                    f"{r['error']} at {r['value']:.3g} {r['unit']} ({-loss:+.3f})" for loss, r in top) + ".",
                f"- **Would buy the most:** {REMEDY.get(top[0][1]['error'], top[0][1]['error'])} "
                f"(recovers up to {top[0][0]:.3f} of the PSF metric)."]
    unit = _unit(task, metric)
    scope = ("" if judged == len(rows) else
             f"; the {judged} errors that cost the most PSF metric were judged through the network")
    return ["- **Limited by** (delivered " + _name(task, metric) + ", network told the nominal PSF" + scope + ") "
            + "; ".join(f"{r['error']} at {r['value']:.3g} {r['unit']} ({loss:.3g}"
                        + (f" ± {noise_of(r, metric):.2g}" if noise_of(r, metric) else "") + f" {unit} worse)"
                        for loss, r in top)
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
        return ["## Simulation grid", "", f"Every error on the {g['monte_carlo_grid']}× grid (chosen by the user: "
                f"`--grid`, or a scene's `tolerance.supersample`). The grid study, which checks each error's bound on "
                f"the grid against the tolerance, did not run: `--grid auto` (a scene without `supersample`) runs it.",
                ""]
    lines = ["## Simulation grid", "",
             f"Each grid-dependent error alone at one standard deviation of the budget on a {g['block_px']}² block of the design, on "
             f"grids 1×, 2×, 4× against {g['reference_grid']}× (bound on the PSF metric's error: twice the summed "
             f"absolute PSF difference over the metric's pixels{_scaled(g)}; tolerance {g['tolerance']}). "
             f"The Monte Carlo runs on the {g['monte_carlo_grid']}× grid. Errors not listed are exact on any grid "
             f"(etch depth, decenter, gap, crosstalk).", "",
             "| error | budget 1σ | bound 1× | bound 2× | bound 4× | its own effect (8×) | grid used |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, v in g["kinds"].items():
        b = v["bound"]
        lines.append(f"| {name} | {v['value']:.3g} {v['unit']} | {b[1] if 1 in b else b['1']:.2g} | "
                     f"{b[2] if 2 in b else b['2']:.2g} | {b[4] if 4 in b else b['4']:.2g} | {v['effect_bound']:.2g} | "
                     f"{v['grid']}× |")
    return lines + [""]


def _scaled(g: dict) -> str:
    """How the grid study brought the block's bound to the whole design (``grid.block_to_full``)."""
    s = g.get("block_to_full")
    return (f", scaled to the whole design by the ratio of the light its metric pixels hold to the block's, "
            f"{min(s):.1f}–{max(s):.1f}× over the bands" if s else "")


def _tornado(res: dict) -> list[str]:
    net = res["level"] == "network"
    lines = ["## Each error alone at one standard deviation of the budget", "", "| error | value | grid | PSF metric | change |"
             + (" delivered change, network told the nominal PSF | told the part's measured PSF |" if net else ""),
             "| --- | --- | --- | --- | --- |" + (" --- | --- |" if net else "")]
    for r in res["tornado"]:
        row = (f"| {r['error']} | {r['value']:.3g} {r['unit']} | {r['grid']}× | {r['metric']:.4f} | "
               f"{signed_change(r['delta'])} |")
        if net:
            d = r.get("network_delta")
            ci = r.get("network_delta_ci95", {})
            row += (" " + " | ".join(delta_text(res["task"], d[lab], ci.get(lab))
                                     for lab in ("nominal_psf", "measured_psf")) + " |" if d
                    else " not judged through the network | |")
        lines.append(row)
    noted = net and any("network_delta_ci95" in r for r in res["tornado"])
    return lines + ([""] + [NOISE_NOTE] if noted else []) + ["", "![tornado](tornado.png)", ""]


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
    m, y, v = res["surrogate"]["model"], res["surrogate"]["yield"], res["surrogate"]["validation"]
    c, curves = m["calibration"], list(m.get("curves", {}))
    signed = lambda ci, f: f"{ci[0]:{f}} to {ci[1]:{f}}"  # noqa: E731
    verdict = ("" if v["consistent"] else " **The surrogate is biased on these parts**: by the difference above "
               "(its interval excludes zero); trust the direct Monte Carlo.")
    return ["## Surrogate", "",
            f"Sensitivity model of the PSF metric in {len(m['names'])} error parameters, fitted on {m['parts']} "
            f"simulated parts, each error alone ({m['seconds']} s): a quadratic through ±h (h = 2σ, or a uniform "
            f"error's bound), or for the {len(curves)} largest losses ({', '.join(curves) or 'none'}) the curve "
            f"through ±h/2, ±h and, for a normal error, ±3h/2. "
            f"Calibrated on {c['n']} parts drawn from the budget: metric = {c['beta']:.3f} × model "
            f"{'+' if c['alpha'] >= 0 else '−'} {abs(c['alpha']):.4f} (RMSE {c['rmse_uncalibrated']:.4f} → "
            f"{c['rmse']:.4f}), with their scatter about it. Yield on {y['draws']} surrogate parts: {y['value']:.3f} "
            f"(95 % interval {interval_text(y['ci95'])}, bootstrap over the calibration parts).", "",
            f"Checked on {v['n']} parts it never saw ({v['parts']}), part by part: surrogate − direct yield "
            f"{v['yield_difference']:+.3f} (95 % interval {signed(v['yield_difference_ci95'], '+.3f')}; "
            f"{v['yield_surrogate']:.3f} against {v['yield_direct']:.3f}), PSF metric {v['metric_difference']:+.4f} "
            f"({signed(v['metric_difference_ci95'], '+.4f')}), RMSE {v['rmse']:.4f}." + verdict, ""]


def _quantization(res: dict) -> list[str]:
    """The quantization table; through the network also what each level count delivers (the task's primary metric)
    and its change from the design's own level count with the change's ± over the judge's scenes."""
    from doefab.tolerance.spec import PRIMARY

    rows, task, n = res["quantization"], res["task"], res.get("n_levels", 16)
    m = PRIMARY.get(task)
    net = m is not None and any("network" in r for r in rows)
    head = f"| levels | quantized from | PSF metric | worst | L1 to the {n}-level PSF |"
    if net:
        head += "".join(f" {_name(task, m)}, network told the {w} | change from {n} levels |"
                        for w in ("nominal PSF", "quantized design's PSF"))
    lines = ["## Quantization", "", head, "| --- " * head.count(" |") + "|"]
    for r in rows:
        line = f"| {r['levels']} | {r.get('source', '')} | " + "".join(
            f"{_number(r.get(k))} | " for k in ("metric", "worst", "l1_to_nominal")).rstrip()
        for lab in ("nominal_psf", "measured_psf") if net else ():
            v = r.get("network", {}).get(lab, {}).get(m)
            d = r.get("network_delta", {}).get(lab, {}).get(m)
            change = "—" if d is None else delta_text(task, {m: d}, r.get("network_delta_ci95", {}).get(lab), False)
            line += f" {'—' if v is None else metric_text(task, m, v)} | {change} |"
        lines.append(line)
    if net and not any(r.get("levels") == n and "network_scenes" in r for r in rows):
        lines += ["", f"The change columns are empty: the design's own {n} levels are not among the level counts "
                      "judged through the network."]
    return lines + ([""] + [NOISE_NOTE] if net and any("network_delta_ci95" in r for r in rows) else []) + [
        "", "![quantization](quantization.png)", ""]


def _number(v) -> str:
    """A PSF figure of the quantization table; "—" where the row has none (its map is not in the folder)."""
    return "—" if v is None or not math.isfinite(v) else f"{v:.4f}"


def _sweeps(res: dict) -> list[str]:
    lines = ["## One error at a time", "", "| error | magnitude | grid | PSF metric | worst | L1 to nominal |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name, s in res["sweeps"].items():
        lines += [f"| {name} | {r['magnitude']} {s['unit']} | {s['grid']}× | {r['metric']:.4f} | {r['worst']:.4f} | "
                  f"{r['l1_to_nominal']:.4f} |" for r in s["rows"]]
    return lines + ["", "![sweeps](sweeps.png)", ""]
