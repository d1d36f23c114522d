"""The tolerance report's figures: sweeps, tornado, quantization, yield against the number of parts, the
distribution of a delivered metric. Units on every axis, every label inside the image (``save_figure``); the
yield band is the same Wilson interval as the tables."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from doefab.plotting import save_figure
from doefab.tolerance.yieldstats import wilson

__all__ = ["sweep_plots", "tornado_plot", "levels_plot", "yield_plot", "distribution_plot"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


METRIC_UNIT = "fraction of coded light in band"  # what the PSF metric is


def sweep_plots(path: Path, sweeps: dict, nominal: float) -> None:
    plt = _plt()
    names = list(sweeps)
    cols = 3
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), layout="constrained", squeeze=False)
    for ax, name in zip(axes.flat, names):
        s = sweeps[name]
        x = [r["magnitude"] for r in s["rows"]]
        ax.plot(x, [r["metric"] for r in s["rows"]], "o-", label="mean")
        ax.plot(x, [r["worst"] for r in s["rows"]], "s--", label="worst entry")
        ax.axhline(nominal, color="grey", ls=":", lw=1, label="nominal")
        ax.set_xlabel(f"{name} ({s['unit']}; grid {s.get('grid', 1)}×)", fontsize=8)
        ax.set_ylabel(METRIC_UNIT, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    save_figure(fig, path, dpi=100)


def tornado_plot(path: Path, rows: list, nominal: float, key: str = "delta", label: str | None = None) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 0.45 * len(rows) + 1.3), layout="constrained")
    names = [f"{r['error']} ({r['value']:.3g} {r['unit']})" for r in rows][::-1]
    vals = [r[key] if key in r else np.nan for r in rows][::-1]
    ax.barh(names, vals, color=["#d65f5f" if (v or 0) < 0 else "#4878cf" for v in vals])
    ax.axvline(0, color="black", lw=0.8)
    ax.set_xlabel(label or f"change of the PSF metric from the nominal {nominal:.3f}\n({METRIC_UNIT})")
    ax.set_title("each error alone at one standard deviation of the budget", fontsize=9)
    ax.tick_params(labelsize=8)
    save_figure(fig, path, dpi=110)


def levels_plot(path: Path, rows: list) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 3.4), layout="constrained")
    labels = [str(r["levels"]) for r in rows]
    ax.plot(labels, [r["metric"] for r in rows], "o-", label="mean")
    ax.plot(labels, [r["worst"] for r in rows], "s--", label="worst entry")
    ax.set_xlabel("quantization (levels)")
    ax.set_ylabel(METRIC_UNIT)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def yield_plot(path: Path, ok: list[bool], spec_text: str) -> None:
    """Running yield with its 95 % Wilson interval against the number of parts."""
    plt = _plt()
    ok = np.asarray(ok, float)
    n = np.arange(1, len(ok) + 1)
    k = np.cumsum(ok)
    y = k / n
    band = np.array([wilson(int(a), int(b)) for a, b in zip(k, n)])
    fig, ax = plt.subplots(figsize=(6, 3.6), layout="constrained")
    ax.plot(n, y, label="running yield")
    ax.fill_between(n, band[:, 0], band[:, 1], alpha=0.3, label="95 % Wilson interval")
    ax.axvline(len(ok), color="red", ls="--", lw=1, label=f"chosen: {len(ok)} parts")
    ax.set_xlabel("Monte Carlo parts")
    ax.set_ylabel("yield (fraction meeting spec)")
    ax.set_title(spec_text, fontsize=8)
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def distribution_plot(path: Path, values: dict, unit: str, name: str, limit: float | None, nominal: float) -> None:
    """Histogram of a delivered metric over the parts, per PSF the network was given."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.6), layout="constrained")
    for label, v in values.items():
        ax.hist(np.asarray(v, float), bins=min(20, max(5, len(v) // 2)), alpha=0.5,
                label=f"network given the {label.replace('_psf', ' PSF').replace('_', ' ')}")
    ax.axvline(nominal, color="grey", ls=":", label=f"nominal part {nominal:.4g}")
    if limit is not None:
        ax.axvline(limit, color="red", ls="--", label=f"spec {limit:.4g}")
    ax.set_xlabel(f"{name} ({unit})" if unit else name)
    ax.set_ylabel("parts")
    ax.legend(fontsize=7)
    save_figure(fig, path, dpi=110)
