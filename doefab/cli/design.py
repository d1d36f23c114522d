"""``doefab design``: optimise a task's DOE and write a design folder (see doefab.design.design)."""

from __future__ import annotations

import argparse
from pathlib import Path

from doefab.errors import DoefabError


def register(sub) -> None:
    p = sub.add_parser("design", help="optimise a streak, grating or half-ring DOE and quantize it to 16 levels",
                       description=__doc__, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--task", required=True, choices=["streak", "grating", "half-ring"], help="task")
    p.add_argument("--out", required=True, help="design folder to write")
    p.add_argument("--iterations", type=int, default=None, help="optimiser steps (default: the task's)")
    p.add_argument("--optimizer", default="adam", choices=["adam", "lbfgs", "mma"], help="optimiser")
    p.add_argument("--lr", type=float, default=None, help="Adam step in waves (default: the task's)")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.add_argument("--sampling", type=int, default=1, help="design on a DOE grid coarser by this factor "
                                                          "(1 = the preset's full grid)")
    p.add_argument("--batch", type=int, default=None, help="(depth, band) pairs per Adam step; 0 = all")
    p.add_argument("--qat-fraction", type=float, default=0.2, help="last fraction of steps run quantization-aware")
    p.add_argument("--fab-weight", type=float, default=0.0, help="isolated-pixel regulariser weight (0 = off)")
    p.add_argument("--checkpoint-every", type=int, default=20, help="steps between checkpoints")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--force", action="store_true", help="overwrite an existing design in OUT")
    p.set_defaults(func=run)


def run(args) -> int:
    import doefab

    out = Path(args.out)
    if (out / "design.json").exists() and not (args.force or args.resume):
        raise DoefabError(f"{out} already holds a design: choose another --out, or --force to overwrite")
    settings = {"qat_fraction": args.qat_fraction, "fab_weight": args.fab_weight,
                "checkpoint_every": args.checkpoint_every, "sampling": args.sampling}
    if args.lr is not None:
        settings["lr"] = args.lr
    if args.batch is not None:
        settings["batch"] = args.batch
    out.mkdir(parents=True, exist_ok=True)
    design = doefab.optimize(args.task, iterations=args.iterations, optimizer=args.optimizer, seed=args.seed,
                             out_dir=out, resume=args.resume, **settings)
    design.save(out)
    m = design.metrics
    print(f"{design.task}: {m['name']}: continuous {m['continuous']:.4f} (worst {m['continuous_worst']:.4f}), "
          f"16-level {m['quantized']:.4f} (worst {m['quantized_worst']:.4f}); "
          f"wall time {design.extra.get('wall_time_s', 0):.0f} s; wrote {out}/")
    return 0
