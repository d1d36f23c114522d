"""The depth-DOE comparison on validation scenes: the table and the winner's PSFs at every plane.

Reads what ``bash scripts/depth_candidates.sh`` wrote under out/depthcand/ (each candidate's proposed depth
network trained the same way, evaluated on 12 validation scenes under honest captures) and writes
benchmarks/results/depth_candidates.md, docs/depth_candidates_psfs.png and docs/depth_winner_psfs_all_planes.png.

    .venv/bin/python benchmarks/depth_candidates_report.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
D = ROOT / "out" / "depthcand"
CANDIDATES = [  # name, design folder, weights folder, label
    ("previous", D / "committed", "committed",  # out/depthcand/committed: the design committed before
     "radial, defocus law, from a lens start of the wrong sign (refocused to ≈ 2.7 m): the previous design"),
    ("radial-seed", D / "radial-seed", "radial-seed", "radial, seed law (r = 25 − 5z), from the refocusing lens"),
    ("radial-defocus", D / "radial-defocus", "radial-defocus",
     "radial, defocus law (r ∝ 1/z − 1/5 m), from the refocusing lens: the committed design"),
]


def main() -> None:
    import doefab
    from doefab.imaging.depth_score import depth_encoding_score
    from doefab.io import read_json
    from doefab.reconstruction.specs import psf_pair

    rows = []
    for name, design, wname, label in CANDIDATES:
        if not (design / "design.json").is_file():
            print(f"skip {name}: no design")
            continue
        d = doefab.Design.load(design)
        pair, sha = psf_pair("depth", design)
        score = depth_encoding_score(pair.coded, pair.depths)
        ev = D / wname / "eval" / "metrics.json"
        meta = D / wname / "weights" / "depth_proposed.json"
        m = read_json(ev)["rows"]["proposed"] if ev.is_file() else {}
        t = read_json(meta)["training"] if meta.is_file() else {}
        rows.append({"name": name, "label": label, "metric": d.metrics["quantized"],
                     "worst": d.metrics["quantized_worst"], "score": score["predicted_error_m"],
                     "min_dprime": score["min_dprime"], "mae": m.get("mae", float("nan")),
                     "delta": m.get("delta125", float("nan")), "rmse": m.get("rmse", float("nan")),
                     "steps": t.get("steps", 0), "train_s": t.get("wall_time_s", 0.0),
                     "design_s": d.extra.get("wall_time_s", float("nan")), "pair": pair})
    lines = ["| candidate | ring metric mean / worst (16-level) | predicted confusion error (m) | min d′ | "
             "validation MAE (m) | δ<1.25 | RMSE (m) | network steps | design wall time (s) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        net = (f"{r['mae']:.3f} | {r['delta']:.3f} | {r['rmse']:.3f}" if np.isfinite(r["mae"])
               else "— (not trained) | — | —")
        lines.append(f"| {r['label']} | {r['metric']:.3f} / {r['worst']:.3f} | {r['score']:.4f} | "
                     f"{r['min_dprime']:.2f} | {net} | {r['steps']} | {r['design_s']:.0f} |")
    trained = [r for r in rows if np.isfinite(r["mae"])]
    by_score = [r["name"] for r in sorted(trained, key=lambda r: r["score"])]
    by_mae = [r["name"] for r in sorted(trained, key=lambda r: r["mae"])]
    lines += ["", "Candidates without a network were not trained (their PSF measures rule them out); the orders "
                  "below are over the trained ones. Split used: validation (12 scenes, honest captures)."]
    lines += ["", f"Order by predicted confusion error: {' < '.join(by_score)}.",
              f"Order by the network's validation MAE: {' < '.join(by_mae)}.",
              f"Orders agree: {'yes' if by_score == by_mae else 'no'}."]
    from doefab.io import atomic_write_text

    out = ROOT / "benchmarks" / "results" / "depth_candidates.md"
    atomic_write_text(out, "\n".join(lines) + "\n")
    print("\n".join(lines))
    best = min(trained, key=lambda r: r["mae"])
    _psf_figure(rows, best["name"])
    _all_planes(best)


def _psf_figure(rows, best: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    planes = [0, 4, 8, 12, 16]
    fig, axes = plt.subplots(len(rows), len(planes), figsize=(2.1 * len(planes), 2.2 * len(rows)),
                             layout="constrained", squeeze=False)
    for i, r in enumerate(rows):
        pair = r["pair"]
        c = pair.coded.numpy().sum(axis=1)  # R+G+B
        k = c.shape[-1]
        lo, hi = k // 2 - 31, k // 2 + 32
        for j, p in enumerate(planes):
            ax = axes[i, j]
            img = c[p, lo:hi, lo:hi]
            im = ax.imshow(img / img.max(), cmap="magma", vmin=0, vmax=1,
                           extent=(-31.5, 31.5, -31.5, 31.5))
            ax.set_title(f"{pair.depths[p]:.0f} m" + (f" — {r['name']}" + (" (winner)" if r["name"] == best else "")
                                                      if j == 0 else ""), fontsize=8)
            ax.tick_params(labelsize=6)
            if j == 0:
                ax.set_ylabel("y (sensor px)", fontsize=7)
            if i == len(rows) - 1:
                ax.set_xlabel("x (sensor px)", fontsize=7)
    cb = fig.colorbar(im, ax=axes, shrink=0.6)
    cb.set_label("coded PSF, R+G+B, / its peak", fontsize=8)
    fig.savefig(ROOT / "docs" / "depth_candidates_psfs.png", dpi=100)
    plt.close(fig)


def _all_planes(r) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pair = r["pair"]
    c = pair.coded.numpy().sum(axis=1)
    k = c.shape[-1]
    lo, hi = k // 2 - 31, k // 2 + 32
    n = c.shape[0]
    cols = 6
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.0 * cols, 2.1 * rows), layout="constrained", squeeze=False)
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.axis("off")
            continue
        img = c[i, lo:hi, lo:hi]
        im = ax.imshow(img / img.max(), cmap="magma", vmin=0, vmax=1, extent=(-31.5, 31.5, -31.5, 31.5))
        ax.set_title(f"z = {pair.depths[i]:.2f} m", fontsize=8)
        ax.tick_params(labelsize=6)
        ax.set_xlabel("x (sensor px)", fontsize=6)
        ax.set_ylabel("y (sensor px)", fontsize=6)
    cb = fig.colorbar(im, ax=axes, shrink=0.6)
    cb.set_label("coded PSF, R+G+B, / its peak", fontsize=8)
    fig.suptitle(f"{r['label']}: coded PSF at every depth plane (16-level, full grid)", fontsize=9)
    fig.savefig(ROOT / "docs" / "depth_winner_psfs_all_planes.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
