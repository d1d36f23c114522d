"""The tolerance report's tables after its summary: grids, tornado, Monte Carlo, surrogate, quantization, sweeps."""

from __future__ import annotations

from doefab.tolerance.montecarlo import interval_text

__all__ = ["body_lines"]


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
            row += (" " + " | ".join(", ".join(f"{k} {v:+.3g}" for k, v in d[lab].items())
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
            f"{k} {d['mean']:.4g} ({interval_text(d['ci95'], '.4g')})" for k, d in v["metrics"].items())
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
