"""``doefab finetune``: end-to-end fine-tuning of a depth DOE together with its depth network, or (--psf) a
network-only fine-tune of any task's network on a fabricated part's measured PSF pair.

Examples:
  doefab finetune --design out/depthcand/radial-defocus --weights-dir out/depthcand/radial-defocus/weights \\
      --minutes 20 --out out/depthcand/e2e
  doefab finetune --psf lab/cal/psf_pair.npz --task hdr --minutes 10 --out out/part7

End to end (--design): writes OUT/design/ (the fine-tuned design: export it with doefab masks), OUT/weights/ (the
jointly trained network), OUT/history.csv (validation depth MAE in metres against wall time) and
OUT/checkpoint.pt.

On a PSF pair (--psf FILE, a psf_pair.npz of doefab calibrate or diagnose; --task): a warm start of the task's
proposed network (the shipped one, or --weights-dir's; --design: the design it was trained for), told the pair
and trained on captures rendered through it with the camera's crosstalk (--clean: without), the DOE untouched.
Writes OUT/weights/ (read it with doefab evaluate --task T --weights-dir OUT/weights --variants proposed --psf
FILE), OUT/history.csv (the validation metric against wall time) and OUT/checkpoint.pt.

Rerun with --resume to continue an interrupted run.
"""

from __future__ import annotations

import argparse
import sys

from doefab.applications import APPLICATIONS, design_is, of_design
from doefab.cli._args import add_device_arg, add_sensor_args, number


def register(sub) -> None:
    p = sub.add_parser("finetune", help="fine-tune a depth DOE with its network, or a network (--psf)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--design", default=None,
                   help="end to end: a half-ring design folder (or mask set) to start from; with --psf: the design "
                        "the network was trained for (default: the committed one)")
    p.add_argument("--psf", default=None, metavar="FILE",
                   help="fine-tune the network alone on this psf_pair.npz (doefab calibrate / diagnose)")
    p.add_argument("--task", default=None, choices=list(APPLICATIONS),
                   help="with --psf: the task whose proposed network is fine-tuned")
    p.add_argument("--crosstalk", default=None, metavar="FILE",
                   help="with --psf: the camera's measured crosstalk.json (doefab calibrate) mixes and unmixes the "
                        "training views instead of the budget's sensor")
    p.add_argument("--weights-dir", default=None,
                   help="start from the network in this folder (end to end: the depth network trained for "
                        "--design, default a fresh one; with --psf: default the shipped one)")
    p.add_argument("--minutes", type=number(float, 0, 1440, lo_open=True, unit="minutes of wall time"), default=20.0,
                   help="wall-time budget")
    p.add_argument("--steps", type=number(int, 1, 10**7, unit="steps"), default=None,
                   help="train this many steps, the learning rate's schedule over them (default: until --minutes "
                        "are spent, the schedule over that time); --minutes still stops the run early")
    p.add_argument("--doe-every", type=number(int, 1, 1000, unit="steps"), default=None,
                   help="end to end: the DOE takes a step every this many network steps (default 4)")
    p.add_argument("--lr-doe", type=number(float, 0, 1, lo_open=True, unit="waves per step"), default=None,
                   help="end to end: DOE Adam step (default 0.01)")
    p.add_argument("--lr-net", type=number(float, 0, 1, lo_open=True), default=2e-4, help="network Adam step")
    p.add_argument("--sampling", type=number(int, 1, 16), default=None,
                   help="end to end: PSF grid coarsening while training (default 2)")
    p.add_argument("--clean", action="store_true", help="with --psf: captures without the camera's crosstalk")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="random seed")
    p.add_argument("--out", required=True, help="output folder")
    add_sensor_args(p, spectral_flag=False)
    add_device_arg(p)
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--force", action="store_true", help="replace an earlier run in OUT")
    p.set_defaults(func=run)


E2E_DEFAULTS = {"doe_every": 4, "lr_doe": 0.01, "sampling": 2}


def run(args) -> int:
    from doefab.cli._args import design_folder, sensor_arg
    from doefab.cli._output import check_resume, checkpoint_hint, claim_output
    from doefab.errors import DoefabError
    from doefab.reconstruction.endtoend import finetune_end_to_end
    from doefab.reconstruction.specs import check_bands

    if args.psf is not None:
        return _run_on_pair(args)
    if args.task is not None or args.clean or args.crosstalk is not None:
        flag = "--task" if args.task else "--clean" if args.clean else "--crosstalk"
        raise DoefabError(f"{flag} is for a network-only fine-tune on a PSF pair (--psf FILE); end-to-end "
                          f"fine-tuning takes a depth design (--design): drop it")
    if args.design is None:
        raise DoefabError("give --design (a half-ring design folder or mask set) to fine-tune a DOE and its network "
                          "end to end, or --psf FILE --task T to fine-tune a network on a measured part's PSF pair")
    for k, v in E2E_DEFAULTS.items():
        setattr(args, k, v if getattr(args, k) is None else getattr(args, k))
    d, design = design_folder(args.design)
    if not design_is(design.task, "depth"):
        raise DoefabError(f"{d}: end-to-end fine-tuning is for depth (half-ring) designs")
    check_bands(of_design(design.task).name, design.wavelengths, d)  # before the output folder is made
    sensor = sensor_arg(args)
    if args.weights_dir is not None:  # the starting network, checked before any PSF is computed
        from doefab.reconstruction.loader import weights_record

        weights_record("depth", "proposed", args.weights_dir, d, sensor=sensor)
    if args.resume and args.force:
        raise DoefabError("--resume continues a run and --force starts one afresh: give one of them")
    out = claim_output(args, "finetune", replace=args.force or args.resume, replace_flag="--force (or --resume)",
                       keep_on_failure=lambda: (args.outdir.path / "checkpoint.pt").is_file())
    if args.resume:
        check_resume(out)
    args.resume_hint = checkpoint_hint(out.path, f"the checkpoint in {out.path} is kept", args.force)
    out.create()
    res = finetune_end_to_end(d, out.path, minutes=args.minutes, weights_dir=args.weights_dir,
                              doe_every=args.doe_every, lr_doe=args.lr_doe, lr_net=args.lr_net,
                              sampling=args.sampling, seed=args.seed, resume=args.resume, sensor=sensor,
                              max_steps=args.steps)
    print(f"end-to-end: {res['steps']} steps in {res['wall_time_s']:.0f} s; validation MAE "
          f"{res['val_mae_start_m']:.3f} → {res['val_mae_end_m']:.3f} m "
          f"({res['mae_gain_per_minute_m'] * 1000:.1f} mm per minute); wrote {res['design']}")
    return 0


def _run_on_pair(args) -> int:
    """``--psf``: the task's proposed network fine-tuned alone on the pair (``partfinetune.finetune_on_pair``)."""
    from doefab.cli._args import sensor_arg, task_design_arg
    from doefab.cli._output import check_resume, checkpoint_hint, claim_output
    from doefab.cli.evaluate import check_psf_args, read_crosstalk_arg, read_psf_arg
    from doefab.errors import DoefabError
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.partfinetune import finetune_on_pair

    if args.task is None:
        raise DoefabError("--psf needs --task (hdr, hyperspectral or depth): the network to fine-tune on the pair")
    given = [f"--{k.replace('_', '-')}" for k in E2E_DEFAULTS if getattr(args, k) is not None]
    if given:
        many = len(given) > 1
        raise DoefabError(f"{', '.join(given)} {'move' if many else 'moves'} the DOE in end-to-end fine-tuning; "
                          f"--psf leaves the DOE untouched: drop {'them' if many else 'it'}")
    if args.resume and args.force:
        raise DoefabError("--resume continues a run and --force starts one afresh: give one of them")
    design = task_design_arg(args, need_weights_dir=True)
    sensor = sensor_arg(args, design)
    pair, record = read_psf_arg(args.psf, "--psf")
    camera = read_crosstalk_arg(args, True)
    out = claim_output(args, "finetune", replace=args.force or args.resume, replace_flag="--force (or --resume)",
                       keep_on_failure=lambda: (args.outdir.path / "checkpoint.pt").is_file())
    if args.resume:
        check_resume(out)
    args.resume_hint = checkpoint_hint(out.path, f"the checkpoint in {out.path} is kept", args.force)
    start = load_reconstructor(args.task, "proposed", args.weights_dir, design, sensor=sensor)
    check_psf_args(args.task, start.pair, pair, None)
    out.create()
    from doefab.tolerance.conditions import measured

    cond = None if args.clean else {s: measured(pair, s, camera=camera) for s in ("train", "val")}
    res = finetune_on_pair(args.task, pair, out.path, args.minutes, conditions=cond, weights_dir=args.weights_dir,
                           design=design, lr=args.lr_net, seed=args.seed, resume=args.resume, max_steps=args.steps,
                           sensor=sensor, records={"told": record, "captured_through": record},
                           command="doefab " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["finetune"]
                           else "doefab finetune")
    print(f"{args.task} on {args.psf}: {res['steps']} steps in {res['wall_time_s']:.0f} s; validation "
          f"{res['metric']} {res['val_start']:.4g} → {res['val_end']:.4g}; wrote {res['weights']}; score it with: "
          f"doefab evaluate --task {args.task} --weights-dir {out.path / 'weights'} --variants proposed "
          f"--psf {args.psf}" + (f" --design {args.design}" if args.design else "") + " --out EVAL_FOLDER")
    return 0
