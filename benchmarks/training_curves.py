"""Validation metric against training wall time for every task and variant (what a 2-minute model buys against
a longer one), from the validation curves shipped beside the weights (doefab/weights/<task>_<variant>_history.csv,
copies of the history.csv that `doefab train` writes). Writes benchmarks/results/training_curves.png.
Run: .venv/bin/python benchmarks/training_curves.py
"""

from __future__ import annotations

import csv
from pathlib import Path

OUT = Path(__file__).parent / "results"
LABELS = {"hdr": "validation PSNR (dB, peak 2^8)", "hyperspectral": "validation PSNR (dB)",
          "depth": "validation MAE (m, lower is better)"}


def main(weights: Path = Path(__file__).resolve().parents[1] / "doefab" / "weights"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), layout="constrained")
    for ax, task in zip(axes, ("hdr", "hyperspectral", "depth")):
        for variant in ("proposed", "coded_only", "uncoded_only"):
            f = weights / f"{task}_{variant}_history.csv"
            if not f.is_file():
                continue
            rows = list(csv.reader(open(f)))[1:]
            pts = [(float(r[1]) / 60, float(r[3])) for r in rows if r[3] not in ("nan", "")]
            xs, ys = [], []
            for x, y in pts:  # the metric is repeated on the rows between validations: keep one point each
                if not ys or y != ys[-1]:
                    xs.append(x)
                    ys.append(y)
            ax.plot(xs, ys, marker=".", label=variant.replace("_", "-"))
        ax.axvline(2, color="grey", ls=":", lw=1)
        ax.set_xlabel("training wall time (minutes, 2-core CPU)")
        ax.set_ylabel(LABELS[task])
        ax.set_title(task)
        ax.legend(fontsize=8)
    OUT.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT / "training_curves.png", dpi=110)


if __name__ == "__main__":
    main()
