"""Design metric against wall time, per task, per optimiser and per pupil sampling.

For each task: the committed design (its 16-level metric and wall time from its design.json; with
--from-designs, a design folder's history.csv gives its curve, e.g. the folders `doefab design` wrote), Adam on
the half-resolution grid (sampling 2) and nlopt L-BFGS on the half grid, both run here from the task's start.
Writes benchmarks/results/design_metric_vs_time.{md,png}.
Run: .venv/bin/python benchmarks/design_metric_vs_time.py
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

OUT = Path(__file__).parent / "results"
CONFIGS = {  # name: (optimizer, sampling, iterations or None for the task default)
    "adam, half grid": ("adam", 2, None),
    "L-BFGS (nlopt), half grid": ("lbfgs", 2, 25),
}


def history_from_folder(folder: Path):
    from doefab.io import read_json

    rows = list(csv.DictReader(open(folder / "history.csv")))
    meta = read_json(folder / "design.json")
    t = np.array([float(r["wall_time_s"]) for r in rows])
    m = np.array([float(r["metric"]) for r in rows])
    return t, m, meta["metrics"]["quantized"], meta.get("extra", {}).get("wall_time_s", t[-1])


def committed_label(task: str) -> str:
    from doefab.design.committed import committed_dir
    from doefab.design.design import Design

    d = Design.load(committed_dir(task))
    cfg = d.extra.get("config", {})
    grid = "full grid" if int(cfg.get("sampling", 1)) == 1 else f"1/{cfg.get('sampling')} grid"
    other = "; optimised on another metric: design.json's metrics.optimised_on" if "optimised_on" in d.metrics else ""
    return (f"the committed design ({cfg.get('optimizer', 'adam')}, {cfg.get('parameterization') or 'pixel'}, {grid}"
            f"{other})")


def committed_run(task: str):
    """(times, metrics, 16-level metric, wall time) of the committed design: no curve, its end point."""
    from doefab.design.committed import committed_dir
    from doefab.design.design import Design

    d = Design.load(committed_dir(task))
    wall = float(d.extra.get("wall_time_s") or float("nan"))
    return np.array([wall]), np.array([d.metrics["quantized"]]), d.metrics["quantized"], wall


def main(argv=None):
    import doefab

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--from-designs", type=Path, help="folder holding <task>/ design folders (full-grid Adam runs)")
    ap.add_argument("--tasks", nargs="+", default=["streak", "grating", "half-ring"])
    args = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    curves, rows = {}, []
    for task in args.tasks:
        runs = {}
        if args.from_designs and (args.from_designs / task / "history.csv").is_file():
            runs["adam, full grid"] = history_from_folder(args.from_designs / task)
        else:
            runs[committed_label(task)] = committed_run(task)
        for name, (opt, sampling, iters) in CONFIGS.items():
            print(f"{task}: {name} …", flush=True)
            d = doefab.optimize(task, iterations=iters, optimizer=opt, sampling=sampling, progress=False,
                                eval_every=5 if opt != "adam" else 20)
            t = np.array([r[1] for r in d.history])
            m = np.array([r[3] for r in d.history])
            runs[name] = (t, m, d.metrics["quantized"], d.extra["wall_time_s"])
        best = max(v[2] for v in runs.values())
        for name, (t, m, q, wall) in runs.items():
            rows.append((task, name, q, wall, "yes" if q >= 0.99 * best else "no"))
        curves[task] = runs
    lines = ["| task | run | 16-level metric (full grid) | wall time (s) | within 1 % of the task's best |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {t} | {n} | {q:.4f} | {w:.0f} | {r} |" for t, n, q, w, r in rows]
    for task in curves:
        ok = [(w, n) for t, n, q, w, r in rows if t == task and r == "yes"]
        w, n = min(ok)
        lines.append(f"\n{task}: a design within 1 % of the best 16-level metric measured here takes {w:.0f} s ({n}).")
    text = "\n".join(lines) + "\n"
    (OUT / "design_metric_vs_time.md").write_text(text)
    print(text)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(5 * len(curves), 4), squeeze=False)
    for ax, (task, runs) in zip(axes[0], curves.items()):
        for name, (t, m, q, w) in runs.items():
            ok = np.isfinite(m)
            ax.plot(t[ok], m[ok], marker="o" if ok.sum() == 1 else None, label=f"{name} (16-level {q:.3f})")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("task metric (design grid, during the run)")
        ax.set_title(task)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "design_metric_vs_time.png", dpi=110)


if __name__ == "__main__":
    main()
