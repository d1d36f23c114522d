"""``doefab design``: optimise a task's DOE and write a design folder (see doefab.design.design).

Interrupted (Ctrl-C) or stopped runs keep OUT/checkpoint.pt: run the same command with --resume to continue
(--resume may also raise --iterations).
"""

from __future__ import annotations


from doefab.applications import DESIGN_TASKS, design_is
from doefab.cli._args import DefaultsHelp, add_device_arg, number
from doefab.errors import DoefabError
from doefab.fabrication.process import DEFAULT_LEVELS, LEVEL_CHOICES


def register(sub) -> None:
    p = sub.add_parser("design", help="optimise a DOE for a task and quantize it to L levels",
                       description=__doc__, formatter_class=DefaultsHelp)
    p.add_argument("--task", required=True, choices=list(DESIGN_TASKS), help="task")
    p.add_argument("--out", required=True, help="design folder to write")
    p.add_argument("--iterations", type=number(int, 1, 1_000_000, unit="steps"), default=None,
                   help="optimiser steps (default: the task's)")
    p.add_argument("--optimizer", default="adam", choices=["adam", "lbfgs", "mma"], help="optimiser")
    p.add_argument("--lr", type=number(float, 0, 10, lo_open=True, unit="waves per step"), default=None,
                   help="Adam step in waves (default: the task's)")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="random seed")
    p.add_argument("--sampling", type=number(int, 1, 16), default=1,
                   help="design on a DOE grid coarser by this factor (1 = the preset's full grid; must divide it)")
    p.add_argument("--batch", type=number(int, -1, 100_000), default=None,
                   help="(depth, band) pairs per Adam step; 0 = all; -1 = every depth, one random band each")
    p.add_argument("--n-levels", "--levels", dest="n_levels", type=int, choices=LEVEL_CHOICES, default=DEFAULT_LEVELS,
                   metavar="L", help="the number of height levels the fab makes: 2, 4, 8, 16 or 32 (log2 L binary "
                                     "masks; --levels is its earlier spelling)")
    p.add_argument("--qat-fraction", type=number(float, 0, 1, unit="fraction of the steps"), default=0.2,
                   help="last fraction of steps run quantization-aware")
    p.add_argument("--fab-weight", type=number(float, 0, 1000), default=0.0,
                   help="isolated-pixel regulariser weight (0 = off)")
    p.add_argument("--checkpoint-every", type=number(int, 1, 1_000_000, unit="steps"), default=20,
                   help="steps between checkpoints")
    p.add_argument("--parameterization", default="pixel", choices=["pixel", "radial"],
                   help="pixel: one phase per DOE pixel; radial: a rotationally symmetric profile θ(r) (linear "
                        "interpolation between --knots radii)")
    p.add_argument("--knots", type=number(int, 2, 100_000, unit="knots"), default=None,
                   help="radial knot count (default: one per design-grid pixel along the radius)")
    p.add_argument("--start", default=None, choices=["task", "lens"],
                   help="starting map: the task's own, or the thin lens that refocuses the coded half to the task's "
                        "farthest depth (default: task for pixel, lens for radial)")
    p.add_argument("--ring-law", default=None, choices=["seed", "defocus"],
                   help="half-ring only: ring radius linear in depth (the paper's Eq. 25) or in inverse depth (defocus)")
    p.add_argument("--loss", default=None, choices=["band", "window", "l1"], help="task loss (default: the task's)")
    add_device_arg(p)
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--force", action="store_true", help="overwrite an existing design in OUT")
    p.set_defaults(func=run)


def run(args) -> int:
    import doefab
    from doefab.cli._output import check_resume, checkpoint_hint, claim_output
    from doefab.design.design import DESIGN_FILES
    from doefab.tasks import get_task

    task = get_task(args.task)
    grid = doefab.Camera.preset(task.preset).doe_pixels
    if grid % args.sampling:
        raise DoefabError(f"--sampling {args.sampling} must divide the {args.task} preset's DOE grid ({grid} px): "
                          f"use one of {[s for s in range(1, 17) if grid % s == 0]}")
    if args.resume and args.force:
        raise DoefabError("--resume continues a run and --force starts one afresh: give one of them")
    out = claim_output(args, "design", replace=args.force or args.resume,
                       replace_flag="--force (or --resume)",
                       keep_on_failure=lambda: (args.outdir.path / "checkpoint.pt").is_file())
    if args.resume:
        check_resume(out)
    args.resume_hint = checkpoint_hint(out.path, f"the checkpoint in {out.path} is kept", args.force)
    settings = {"qat_fraction": args.qat_fraction, "fab_weight": args.fab_weight,
                "checkpoint_every": args.checkpoint_every, "sampling": args.sampling, "n_levels": args.n_levels}
    if args.lr is not None:
        settings["lr"] = args.lr
    if args.batch is not None:
        settings["batch"] = args.batch
    if args.knots is not None and args.parameterization != "radial":
        raise DoefabError("--knots applies to --parameterization radial only")
    if args.ring_law and not design_is(args.task, "depth"):
        raise DoefabError(f"--ring-law applies to the half-ring task, not {args.task}")
    settings.update(parameterization=args.parameterization, knots=args.knots or 0, start=args.start)
    params = {}
    if args.ring_law:
        params["ring_law"] = args.ring_law
    if args.loss:
        params["loss_kind"] = args.loss
    if params:
        settings["task_params"] = params
    out.create()
    # --force: the earlier design's files go as the run starts, after every check (design.json too), so an
    # interrupted run leaves no complete-looking design of the old settings beside its checkpoint
    design = doefab.optimize(args.task, iterations=args.iterations, optimizer=args.optimizer, seed=args.seed,
                             out_dir=out.path, resume=args.resume, replace=DESIGN_FILES if args.force else (),
                             **settings)
    design.save(out.path)
    m = design.metrics
    stop = design.extra.get("stop_reason")
    print(f"{design.task}: {m['name']}: continuous {m['continuous']:.4f} (worst {m['continuous_worst']:.4f}), "
          f"{design.n_levels}-level {m['quantized']:.4f} (worst {m['quantized_worst']:.4f}); "
          f"wall time {design.extra.get('wall_time_s', 0):.0f} s; wrote {out.path}/"
          + (f"; optimiser: {stop}" if stop else ""))
    return 0
