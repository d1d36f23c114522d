"""Run the requested studies and write tolerance.json, report.md and the plots (units on every axis)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from doefab.io import atomic_write_json, atomic_write_text
from doefab.tolerance import study

__all__ = ["run_study"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def run_study(design_dir: Path, budget: dict, out: Path, samples: int = 20, seed: int = 0, supersample: int = 1,
              do_sweep: bool = False, do_levels: bool = False, workers: int = 1, scheduler=None,
              budget_path=None, networks: bool = False) -> dict:
    res: dict = {"design": str(design_dir), "supersample": supersample, "seed": seed,
                 "budget_file": str(budget_path or "doefab/tolerance/budget.toml (default)"), "budget": budget}
    md = [f"# Tolerance study of `{design_dir}`", "",
          f"PSF-level judgement (task metric = fraction of the coded light in the task's band; L1 = summed absolute "
          f"difference to the nominal 16-level PSF, mean over bands and depths). Simulation grid: {supersample}× the "
          f"DOE pixel. Budget: `{res['budget_file']}`.", ""]
    spec = float(budget.get("spec", {}).get("metric_min", 0.0))
    judge = study._judge(str(design_dir), supersample)
    res["nominal"] = judge.score(judge.nominal)
    md += [f"Nominal (16-level, no errors): metric {res['nominal']['metric']:.4f}, worst entry "
           f"{res['nominal']['worst']:.4f}.", ""]
    if do_sweep:
        t = time.perf_counter()
        sw = study.sweep(design_dir, supersample)
        res["sweeps"] = sw["sweeps"]
        res["tornado"] = study.tornado(design_dir, budget, supersample)
        res["sweep_seconds"] = round(time.perf_counter() - t, 1)
        _sweep_plots(out, sw, res["nominal"]["metric"])
        _tornado_plot(out / "tornado.png", res["tornado"], res["nominal"]["metric"])
        md += ["## One error at a time", "", "| error | magnitude | metric | worst | L1 to nominal |",
               "| --- | --- | --- | --- | --- |"]
        for name, s in sw["sweeps"].items():
            for r in s["rows"]:
                md.append(f"| {name} | {r['magnitude']} {s['unit']} | {r['metric']:.4f} | {r['worst']:.4f} | "
                          f"{r['l1_to_nominal']:.4f} |")
        md += ["", "Tornado at the budget's values (each error alone):", "", "| error | metric | change |",
               "| --- | --- | --- |"]
        md += [f"| {r['error']} | {r['metric']:.4f} | {r['delta']:+.4f} |" for r in res["tornado"]]
        md += ["", "![sweeps](sweeps.png)", "", "![tornado](tornado.png)", ""]
    if do_levels:
        res["quantization"] = study.quantization_study(design_dir, supersample=supersample, networks=networks)
        md += ["## Quantization", "", "| levels | metric | worst | L1 to the 16-level PSF |", "| --- | --- | --- | --- |"]
        md += [f"| {r['levels']} | {r['metric']:.4f} | {r['worst']:.4f} | {r['l1_to_nominal']:.4f} |"
               for r in res["quantization"]]
        with_net = [r for r in res["quantization"] if "network" in r]
        if networks and with_net:
            first = with_net[0]["network"]["nominal_psf"]
            md += ["", "Through the shipped proposed network (given the nominal PSF / the quantized design's PSF):", "",
                   "| levels | " + " | ".join(f"{k} (nominal PSF) | {k} (measured PSF)" for k in first) + " |",
                   "| --- |" + " --- |" * (2 * len(first))]
            for r in with_net:
                n = r["network"]
                md.append(f"| {r['levels']} | " + " | ".join(f"{n['nominal_psf'][k]:.4g} | {n['measured_psf'][k]:.4g}"
                                                            for k in first) + " |")
        _levels_plot(out / "quantization.png", res["quantization"])
        md += ["", "![quantization](quantization.png)", ""]
    if samples > 0:
        t = time.perf_counter()
        rows = study.monte_carlo(design_dir, budget, samples, out, seed=seed, supersample=supersample,
                                 scheduler=scheduler, workers=workers, networks=networks)
        res["monte_carlo_seconds"] = round(time.perf_counter() - t, 1)
        res["samples"] = rows
        res["summary"] = study.summarize(rows, spec)
        conv = []
        for n in sorted({k for k in (5, 10, 20, 40, 80, 160, 320, 640, samples) if 2 <= k <= samples}):
            s = study.summarize(rows[:n], spec)
            conv.append({"n": n, "metric_ci95_width": s["metric"]["ci95_width"],
                         "yield_ci95_width": s["yield"]["ci95"][1] - s["yield"]["ci95"][0],
                         "seconds": max(r["seconds"] for r in rows[:n])})
        res["convergence"] = conv
        s = res["summary"]
        md += ["## Monte Carlo", "",
               f"{samples} parts (seed {seed}); metric mean {s['metric']['mean']:.4f}, 95 % interval of the mean "
               f"{s['metric']['ci95'][0]:.4f}–{s['metric']['ci95'][1]:.4f}; yield (metric ≥ {spec}) "
               f"{s['yield']['value']:.3f}, 95 % interval {s['yield']['ci95'][0]:.3f}–{s['yield']['ci95'][1]:.3f}; "
               f"{res['monte_carlo_seconds']} s.", "",
               "| samples | metric CI width | yield CI width | wall time (s) |", "| --- | --- | --- | --- |"]
        md += [f"| {c['n']} | {c['metric_ci95_width']:.4f} | {c['yield_ci95_width']:.3f} | {c['seconds']:.0f} |"
               for c in conv]
        if networks and rows and "network" in rows[0]:
            net = {lab: {k: float(np.nanmean([r["network"][lab][k] for r in rows])) for k in rows[0]["network"][lab]}
                   for lab in rows[0]["network"]}
            res["summary"]["network"] = net
            md += ["", "Through the shipped proposed network (mean over samples; a fixed test subset per sample):", "",
                   "| network given | " + " | ".join(net["nominal_psf"]) + " |",
                   "| --- |" + " --- |" * len(net["nominal_psf"])]
            for lab, vals in net.items():
                md.append(f"| {lab.replace('_', ' ')} | " + " | ".join(f"{v:.4g}" for v in vals.values()) + " |")
        _convergence_plot(out / "yield_vs_n.png", rows, spec)
        md += ["", "![yield against N](yield_vs_n.png)", ""]
    atomic_write_json(out / "tolerance.json", res)
    atomic_write_text(out / "report.md", "\n".join(md) + "\n")
    return res


def _sweep_plots(out: Path, sw: dict, nominal: float) -> None:
    plt = _plt()
    names = list(sw["sweeps"])
    cols = 3
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), layout="constrained", squeeze=False)
    for ax, name in zip(axes.flat, names):
        s = sw["sweeps"][name]
        x = [r["magnitude"] for r in s["rows"]]
        ax.plot(x, [r["metric"] for r in s["rows"]], "o-", label="mean")
        ax.plot(x, [r["worst"] for r in s["rows"]], "s--", label="worst entry")
        ax.axhline(nominal, color="grey", ls=":", lw=1, label="nominal")
        ax.set_xlabel(f"{name} ({s['unit']})", fontsize=8)
        ax.set_ylabel("fraction of coded light in band", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    fig.savefig(out / "sweeps.png", dpi=100)
    plt.close(fig)


def _tornado_plot(path: Path, rows: list, nominal: float) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 0.45 * len(rows) + 1.2), layout="constrained")
    names = [r["error"] for r in rows][::-1]
    ax.barh(names, [r["delta"] for r in rows][::-1], color=["#d65f5f" if r["delta"] < 0 else "#4878cf"
                                                             for r in rows][::-1])
    ax.axvline(0, color="black", lw=0.8)
    ax.set_xlabel(f"change of the task metric (fraction of coded light) from the nominal {nominal:.3f}")
    ax.set_title("each error alone at its budget value", fontsize=9)
    ax.tick_params(labelsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _levels_plot(path: Path, rows: list) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 3.4), layout="constrained")
    labels = [str(r["levels"]) for r in rows]
    ax.plot(labels, [r["metric"] for r in rows], "o-", label="mean")
    ax.plot(labels, [r["worst"] for r in rows], "s--", label="worst entry")
    ax.set_xlabel("quantization (levels)")
    ax.set_ylabel("fraction of coded light in band")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _convergence_plot(path: Path, rows: list, spec: float) -> None:
    plt = _plt()
    ok = np.array([r["metric"] >= spec for r in rows], float)
    n = np.arange(1, len(ok) + 1)
    y = np.cumsum(ok) / n
    half = 1.96 * np.sqrt(np.maximum(y * (1 - y), 1e-12) / n)
    fig, ax = plt.subplots(figsize=(5.5, 3.4), layout="constrained")
    ax.plot(n, y, label="running yield")
    ax.fill_between(n, np.clip(y - half, 0, 1), np.clip(y + half, 0, 1), alpha=0.3, label="95 % interval")
    ax.axvline(len(ok), color="red", ls="--", lw=1, label=f"chosen: {len(ok)} samples")
    ax.set_xlabel("Monte Carlo samples (parts)")
    ax.set_ylabel(f"yield (fraction with metric ≥ {spec})")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)
