"""Which training crop (and loss) for the depth networks? Proposed depth networks trained the same number of
steps from scratch under honest captures, scored on VALIDATION scenes (split used: val; this is the choice of a
training setting, the test split is for the final tables).

    .venv/bin/python benchmarks/depth_training_pilot.py [--steps 500] [--images 12] [--work out/depth_pilot]

Runs: the training crop at 96, 128 and 160 px with the shipped loss (Eq. 28: L1 + gradient on depth), a second
seed at 128 px (the seed sets the initial weights: the spread between two seeds says which differences are
noise), and 128 px with Eq. 28 applied to log depth (δ<1.25 is a ratio: a loss on log depth weighs near and far
errors alike). A run whose weights are already in WORK/<run>/weights is not trained again. The shipped proposed
network (the chosen setting, trained again by scripts/train_shipped.sh) is scored beside them: its distance from
the run with the same setting is the run-to-run spread. Writes benchmarks/results/depth_training_crop.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_text  # noqa: E402
import doefab.reconstruction.models as models  # noqa: E402
import doefab.reconstruction.train as train_mod  # noqa: E402
from doefab.reconstruction.evaluate import evaluate  # noqa: E402
from doefab.reconstruction.loader import load_reconstructor  # noqa: E402
from doefab.reconstruction.depthnet import depth_loss  # noqa: E402
from doefab.tolerance.conditions import for_splits  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
SHIPPED = models.loss_fn


def log_depth(task, pred, target):
    """Eq. 28 on log depth."""
    return depth_loss(torch.log(pred.clamp_min(1e-3)), torch.log(target))


RUNS = (("crop96_seed0", 96, 0, SHIPPED), ("crop128_seed0", 128, 0, SHIPPED), ("crop128_seed1", 128, 1, SHIPPED),
        ("crop160_seed0", 160, 0, SHIPPED), ("crop128_seed0_logloss", 128, 0, log_depth))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--work", default="out/depth_pilot", help="where each run's weights are kept")
    args = ap.parse_args()
    cond = for_splits("depth", None, "honest", ("train", "val"))
    rows = {}
    for name, crop, seed, fn in RUNS:
        w = Path(args.work) / name
        if not (w / "weights" / "depth_proposed.pt").is_file():
            train_mod.loss_fn = fn  # the training loop's loss
            try:
                train_mod.train("depth", "proposed", 600, w / "run", weights_dir=w / "weights", conditions=cond,
                                max_steps=args.steps, progress=False, seed=seed, crop=crop)
            finally:
                train_mod.loss_fn = SHIPPED
        r = evaluate("depth", w / "eval", images=args.images, size=256, weights_dir=w / "weights",
                     variants=("proposed",), conditions=cond["val"], split="val", progress=False)
        rows[name] = (crop, seed, "Eq. 28 on depth" if fn is SHIPPED else "Eq. 28 on log depth", r["rows"]["proposed"])
        print(name, rows[name][-1], flush=True)
    r = evaluate("depth", Path(args.work) / "shipped_eval", images=args.images, size=256, variants=("proposed",),
                 conditions=cond["val"], split="val", progress=False)
    tr = load_reconstructor("depth").meta["training"]
    rows["shipped"] = (tr["crop_px"], tr["seed"], f"Eq. 28 on depth: the shipped network ({tr['steps']} steps, "
                       f"{tr['wall_time_s']:.0f} s)", r["rows"]["proposed"])
    atomic_write_text(OUT / "depth_training_crop.md", table(rows, args) + "\n")
    print(table(rows, args))


def table(rows: dict, args) -> str:
    lines = [f"Proposed depth networks, {args.steps} steps each from scratch under honest captures, on "
             f"{args.images} validation scenes of 256² px (`.venv/bin/python "
             f"benchmarks/depth_training_pilot.py --steps {args.steps} --images {args.images}`).", "",
             "| training crop (px) | seed | loss | MAE (m) | RMSE (m) | δ<1.25 |", "| --- | --- | --- | --- | --- | --- |"]
    for crop, seed, loss, m in rows.values():
        lines.append(f"| {crop} | {seed} | {loss} | {m['mae']:.3f} | {m['rmse']:.3f} | {m['delta125']:.3f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
