"""``doefab train``: train a reconstruction network for the committed design of a task (CPU, minutes).

Training captures are made as a real camera makes them — through fabricated parts drawn from the default
tolerance budget, with per-column dual-pixel crosstalk unmixed by a noisy calibration and depth between the
network's planes (each split its own parts) — while the network is told the nominal PSF; --clean trains on the
nominal model's own captures.

Writes the weights and their metadata record (<task>_<variant>.pt/.json) into OUT, or into --weights-dir;
the shipped weights in doefab/weights/ are replaced only with --replace-shipped. OUT/checkpoint.pt and
OUT/history.csv are written every 50 steps (at each validation) and at the end.
Interrupted runs keep the last checkpoint: rerun the same command with --resume (it may raise --minutes; with the
cosine schedule over the time budget, without --steps, a larger budget stretches the decay, so the learning rate
rises again; with --steps the schedule runs over the steps).
"""

from __future__ import annotations

import sys
from pathlib import Path

from doefab.applications import APPLICATIONS
from doefab.cli._args import DefaultsHelp, add_device_arg, add_sensor_args, number


def register(sub) -> None:
    p = sub.add_parser("train", help="train a reconstruction network on this machine",
                       description=__doc__, formatter_class=DefaultsHelp)
    p.add_argument("--task", required=True, choices=list(APPLICATIONS), help="task")
    p.add_argument("--variant", default="proposed", choices=["proposed", "coded_only", "uncoded_only"],
                   help="network variant (the ablations use the same architecture and budget)")
    p.add_argument("--minutes", type=number(float, 0, 1440, lo_open=True, unit="minutes of wall time"), default=10.0,
                   help="training budget in minutes of wall time")
    p.add_argument("--steps", type=number(int, 1, 10**7, unit="steps"), default=None,
                   help="train this many steps, the learning rate's schedule over them (a budget a loaded machine "
                        "cannot shrink, the same weights every run: for comparisons); --minutes still stops the run "
                        "early, and the record and output say so")
    p.add_argument("--out", default=None, help="run folder for checkpoint.pt and history.csv "
                                               "(default out/train/<task>_<variant>)")
    p.add_argument("--weights-dir", default=None, help="where to write the weights (default: OUT)")
    p.add_argument("--replace-shipped", action="store_true",
                   help="write the weights over the shipped ones in doefab/weights/ (the committed design only)")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="random seed")
    p.add_argument("--batch", type=number(int, 1, 64), default=4, help="scenes per step")
    p.add_argument("--crop", type=number(int, 64, 512, unit="pixels; a multiple of 32"), default=None,
                   help="training crop side in pixels (default: the task's: 96; depth 128)")
    p.add_argument("--lr", type=number(float, 0, 1, lo_open=True), default=1e-3, help="Adam learning rate at the start")
    p.add_argument("--schedule", default="cosine", choices=["cosine", "constant"],
                   help="learning rate over the run (--steps, else the wall-time budget): cosine decay to 5 %% of "
                        "--lr, or constant")
    p.add_argument("--design", default=None,
                   help="train for this design folder (or mask set) instead of the committed one")
    p.add_argument("--clean", action="store_true",
                   help="train on the nominal model's own captures instead of each split's fabricated parts, "
                        "crosstalk and off-plane depth")
    add_sensor_args(p)
    add_device_arg(p)
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--force", action="store_true", help="replace an earlier training run in OUT")
    p.set_defaults(func=run)


def run(args) -> int:
    from doefab.cli._args import sensor_arg, task_design_arg
    from doefab.cli._output import check_resume, claim_output, clear_earlier_run, resume_hint
    from doefab.errors import DoefabError
    from doefab.reconstruction.specs import training_crop
    from doefab.reconstruction.train import train
    from doefab.reconstruction.weights import history_path, weights_paths, weights_target

    training_crop(args.task, args.crop)  # train() resolves it again; checked here before any output is claimed
    args.memory_hint = "lower --batch or --crop (each step holds its batch's scenes and activations)"
    if args.resume and args.force:
        raise DoefabError("--resume continues a run and --force starts one afresh: give one of them")
    args.out = f"out/train/{args.task}_{args.variant}" if args.out is None else args.out
    out = claim_output(args, "train", replace=args.force or args.resume, replace_flag="--force (or --resume)",
                       keep_on_failure=lambda: (args.outdir.path / "checkpoint.pt").is_file())
    if args.resume:
        check_resume(out)
    args.resume_hint = resume_hint(f"the checkpoint in {out.path} is kept", args.force)
    design = task_design_arg(args, need_weights_dir=False)
    sensor = sensor_arg(args, design)
    target = weights_target(args.weights_dir, out.path, args.replace_shipped, design, args.task, args.variant)
    clear_earlier_run(out, args.force, [out.path / "warm_start.json"] + (  # and its weights where these go there
        [*weights_paths(args.task, args.variant, out.path), history_path(args.task, args.variant, out.path)]
        if Path(target).resolve() == out.path.resolve() else []))
    out.create()
    from doefab.tolerance.conditions import for_splits

    cond = None if args.clean else for_splits(args.task, design, "honest", progress=True)
    meta = train(args.task, args.variant, args.minutes, out.path, resume=args.resume, seed=args.seed,
                 batch=args.batch, crop=args.crop, lr=args.lr, weights_dir=args.weights_dir, design=design,
                 schedule=args.schedule, replace_shipped=args.replace_shipped, command=_command_line(),
                 conditions=cond, max_steps=args.steps, sensor=sensor)
    v = {k: round(x, 4) for k, x in meta["validation"].items() if isinstance(x, float)}
    if meta["training"].get("stopped"):
        print(f"note: {meta['training']['stopped']}")
    print(f"{args.task} {args.variant}: {meta['training']['steps']} steps in {meta['training']['wall_time_s']:.0f} s; "
          f"validation {v}; wrote {meta['weights_path']} and its .json")
    return 0


def _command_line() -> str:
    """The command that trained the weights, for their metadata: ``doefab train ...`` whether it ran as the
    ``doefab`` script or as ``python -m doefab``; ``doefab train`` alone when called from Python."""
    argv0 = sys.argv[0].replace("\\", "/")
    if argv0.endswith("/doefab") or argv0 == "doefab" or argv0.endswith("doefab/__main__.py"):
        return "doefab " + " ".join(sys.argv[1:])
    return "doefab train"
