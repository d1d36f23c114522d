"""Does the HDR loss's highlight term earn its place? Two uncoded-only HDR networks trained the same number of
steps from scratch under honest captures, one with the shipped loss (L1 of log radiance plus the highlights'
relative linear L1), one with the log term alone, scored on VALIDATION scenes (split used: val; this is the
choice of the loss, the test split is for the final tables).

    .venv/bin/python benchmarks/hdr_loss_pilot.py [--steps 150] [--images 12] [--seeds 3]

Each loss is trained once per seed (the seed sets the initial weights and the training crops; both losses see the
same seeds), so the difference between the losses is read against the spread between seeds. Writes
benchmarks/results/hdr_loss_pilot.md: Table 1's metrics of each run on the validation scenes, the mean per loss,
and the per-seed difference.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_text  # noqa: E402
import doefab.reconstruction.models as models  # noqa: E402
import doefab.reconstruction.train as train_mod  # noqa: E402
from doefab.reconstruction.evaluate import evaluate  # noqa: E402
from doefab.tolerance.conditions import for_splits  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"


def log_only(task, pred, target):
    if task != "hdr":
        return SHIPPED(task, pred, target)
    return (torch.log1p(pred) - torch.log1p(target)).abs().mean()


SHIPPED = models.loss_fn


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    losses = (("log L1 + highlights' relative L1 (shipped)", SHIPPED), ("log L1 alone", log_only))
    rows: dict = {}
    cond = for_splits("hdr", None, "honest", ("train", "val"))
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            for name, fn in losses:
                train_mod.loss_fn = fn  # the training loop's loss
                w = Path(tmp) / f"{'shipped' if fn is SHIPPED else 'log_only'}_{seed}"
                train_mod.train("hdr", "uncoded_only", 600, w / "run", weights_dir=w / "weights", conditions=cond,
                                max_steps=args.steps, progress=False, seed=seed)
                r = evaluate("hdr", w / "eval", images=args.images, size=256, weights_dir=w / "weights",
                             variants=("uncoded_only",), conditions=cond["val"], split="val", progress=False)
                rows[(name, seed)] = r["rows"]["uncoded_only"]
                print(name, seed, rows[(name, seed)], flush=True)
    train_mod.loss_fn = SHIPPED
    atomic_write_text(OUT / "hdr_loss_pilot.md", table(rows, losses, args) + "\n")
    print(table(rows, losses, args))


def table(rows: dict, losses: tuple, args) -> str:
    keys = ("psnr", "psnr_highlight", "rmse", "rmse_highlight")
    fmt = lambda m: f"{m['psnr']:.2f} | {m['psnr_highlight']:.2f} | {m['rmse']:.3f} | {m['rmse_highlight']:.2f}"
    lines = [f"Uncoded-only HDR networks, {args.steps} steps each from scratch under honest captures, seeds 0–"
             f"{args.seeds - 1} per loss, on {args.images} validation scenes of 256² px (`.venv/bin/python "
             f"benchmarks/hdr_loss_pilot.py --steps {args.steps} --images {args.images} --seeds {args.seeds}`).", "",
             "| loss | seed | PSNR (dB) | highlight PSNR (dB) | RMSE | highlight RMSE |",
             "| --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {n} | {s} | {fmt(m)} |" for (n, s), m in rows.items()]
    seeds = range(args.seeds)
    for n, _ in losses:
        mean = {k: sum(rows[(n, s)][k] for s in seeds) / args.seeds for k in keys}
        lines.append(f"| {n} | mean | {fmt(mean)} |")
    (a, _), (b, _) = losses
    diff = [rows[(b, s)]["psnr_highlight"] - rows[(a, s)]["psnr_highlight"] for s in seeds]
    lines += ["", "Highlight PSNR of the log term alone minus the shipped loss, per seed: "
              + ", ".join(f"{d:+.2f}" for d in diff) + " dB."]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
