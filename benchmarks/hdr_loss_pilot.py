"""Does a highlight term earn its place in the HDR loss? Uncoded-only HDR networks trained the same number of
steps from scratch under honest captures, with the log term alone (L1 of log radiance: the shipped loss) and with
the highlights' relative linear L1 added (the paper's Eq. 20 has a highlight term), scored on VALIDATION scenes
(split used: val; this is the choice of the loss, the test split is for the final tables).

    .venv/bin/python benchmarks/hdr_loss_pilot.py [--steps 150] [--images 12] [--seeds 3]

Each loss is trained once per seed (the seed sets the initial weights and the training crops; both losses see the
same seeds), so the difference between the losses is read seed by seed. Writes benchmarks/results/hdr_loss_pilot.md:
Table 1's metrics of each run on the validation scenes, the mean per loss, and the paired difference per seed
with its 95 % t-interval.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_text  # noqa: E402
import doefab.reconstruction.models as models  # noqa: E402
import doefab.reconstruction.train as train_mod  # noqa: E402
from doefab.reconstruction.evaluate import evaluate  # noqa: E402
from doefab.reconstruction.metrics import HIGHLIGHT_ABOVE  # noqa: E402
from doefab.tolerance.conditions import for_splits  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
SHIPPED = models.loss_fn


def log_l1(pred, target):
    return (torch.log1p(pred) - torch.log1p(target)).abs().mean()


def log_only(task, pred, target):
    return log_l1(pred, target) if task == "hdr" else SHIPPED(task, pred, target)


def with_highlight_term(task, pred, target):
    """The log term plus the L1 of the highlight pixels (radiance above HIGHLIGHT_ABOVE in any channel) relative
    to their total radiance."""
    if task != "hdr":
        return SHIPPED(task, pred, target)
    hl = (target > HIGHLIGHT_ABOVE).any(dim=1, keepdim=True).expand_as(pred)
    return log_l1(pred, target) + ((pred - target).abs() * hl).sum() / (target * hl).sum().clamp_min(1e-6)


LOSSES = (("log L1 + highlights' relative L1", with_highlight_term), ("log L1 alone (shipped)", log_only))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    rows: dict = {}
    cond = for_splits("hdr", None, "honest", ("train", "val"))
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            for i, (name, fn) in enumerate(LOSSES):
                train_mod.loss_fn = fn  # the training loop's loss
                w = Path(tmp) / f"loss{i}_{seed}"
                train_mod.train("hdr", "uncoded_only", 600, w / "run", weights_dir=w / "weights", conditions=cond,
                                max_steps=args.steps, progress=False, seed=seed)
                r = evaluate("hdr", w / "eval", images=args.images, size=256, weights_dir=w / "weights",
                             variants=("uncoded_only",), conditions=cond["val"], split="val", progress=False)
                rows[(name, seed)] = r["rows"]["uncoded_only"]
                print(name, seed, rows[(name, seed)], flush=True)
    train_mod.loss_fn = SHIPPED
    atomic_write_text(OUT / "hdr_loss_pilot.md", table(rows, args) + "\n")
    print(table(rows, args))


def table(rows: dict, args) -> str:
    keys = ("psnr", "psnr_highlight", "rmse", "rmse_highlight")
    fmt = lambda m: f"{m['psnr']:.2f} | {m['psnr_highlight']:.2f} | {m['rmse']:.3f} | {m['rmse_highlight']:.2f}"
    lines = [f"Uncoded-only HDR networks, {args.steps} steps each from scratch under honest captures, seeds 0–"
             f"{args.seeds - 1} per loss, on {args.images} validation scenes of 256² px (`.venv/bin/python "
             f"benchmarks/hdr_loss_pilot.py --steps {args.steps} --images {args.images} --seeds {args.seeds}`).", "",
             "| loss | seed | PSNR (dB) | highlight PSNR (dB) | RMSE | highlight RMSE |",
             "| --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {n} | {s} | {fmt(m)} |" for (n, s), m in rows.items()]
    seeds = range(args.seeds)
    for n, _ in LOSSES:
        mean = {k: sum(rows[(n, s)][k] for s in seeds) / args.seeds for k in keys}
        lines.append(f"| {n} | mean | {fmt(mean)} |")
    (a, _), (b, _) = LOSSES
    d = np.array([rows[(b, s)]["psnr_highlight"] - rows[(a, s)]["psnr_highlight"] for s in seeds])
    text = ", ".join(f"{x:+.3f}" for x in d)
    if len(d) > 1:
        half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
        text += f"; mean {d.mean():+.2f} dB, 95 % t-interval {d.mean() - half:+.2f} to {d.mean() + half:+.2f} dB"
    lines += ["", f"Highlight PSNR of the log term alone minus the loss with the highlight term, seed by seed: {text}."]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
