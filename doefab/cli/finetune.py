"""``doefab finetune``: end-to-end fine-tuning of a depth DOE together with its depth network.

Examples:
  doefab finetune --design out/depthcand/radial-defocus --weights-dir out/depthcand/radial-defocus/weights \\
      --minutes 20 --out out/depthcand/e2e

Writes OUT/design/ (the fine-tuned design: export it with doefab masks), OUT/weights/ (the jointly trained
network), OUT/history.csv (validation depth MAE in metres against wall time) and OUT/checkpoint.pt; rerun
with --resume to continue an interrupted run.
"""

from __future__ import annotations

import argparse

from doefab.cli._args import add_device_arg, add_sensor_args, number


def register(sub) -> None:
    p = sub.add_parser("finetune", help="fine-tune a depth DOE and its network end to end",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--design", required=True, help="a half-ring design folder (or mask set) to start from")
    p.add_argument("--weights-dir", default=None,
                   help="start from the depth network trained for that design (doefab train --design ... "
                        "--weights-dir ...); default: a fresh network")
    p.add_argument("--minutes", type=number(float, 0, 1440, lo_open=True, unit="minutes of wall time"), default=20.0,
                   help="wall-time budget")
    p.add_argument("--doe-every", type=number(int, 1, 1000, unit="steps"), default=4,
                   help="the DOE takes a step every this many network steps")
    p.add_argument("--lr-doe", type=number(float, 0, 1, lo_open=True, unit="waves per step"), default=0.01,
                   help="DOE Adam step")
    p.add_argument("--lr-net", type=number(float, 0, 1, lo_open=True), default=2e-4, help="network Adam step")
    p.add_argument("--sampling", type=number(int, 1, 16), default=2, help="PSF grid coarsening while training")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="random seed")
    p.add_argument("--out", required=True, help="output folder")
    add_sensor_args(p, spectral_flag=False)
    add_device_arg(p)
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--force", action="store_true", help="replace an earlier run in OUT")
    p.set_defaults(func=run)


def run(args) -> int:
    from doefab.cli._args import design_folder, sensor_arg
    from doefab.cli._output import check_resume, claim_output
    from doefab.errors import DoefabError
    from doefab.reconstruction.endtoend import finetune_end_to_end

    d, design = design_folder(args.design)
    if design.task != "half-ring":
        raise DoefabError(f"{d}: end-to-end fine-tuning is for depth (half-ring) designs")
    sensor = sensor_arg(args)
    if args.resume and args.force:
        raise DoefabError("--resume continues a run and --force starts one afresh: give one of them")
    out = claim_output(args, "finetune", replace=args.force or args.resume, replace_flag="--force (or --resume)",
                       keep_on_failure=lambda: (args.outdir.path / "checkpoint.pt").is_file())
    if args.resume:
        check_resume(out)
    args.resume_hint = f"the checkpoint in {out.path} is kept: rerun the same command with --resume to continue"
    out.create()
    res = finetune_end_to_end(d, out.path, minutes=args.minutes, weights_dir=args.weights_dir,
                              doe_every=args.doe_every, lr_doe=args.lr_doe, lr_net=args.lr_net,
                              sampling=args.sampling, seed=args.seed, resume=args.resume, sensor=sensor)
    print(f"end-to-end: {res['steps']} steps in {res['wall_time_s']:.0f} s; validation MAE "
          f"{res['val_mae_start_m']:.3f} → {res['val_mae_end_m']:.3f} m "
          f"({res['mae_gain_per_minute_m'] * 1000:.1f} mm per minute); wrote {res['design']}")
    return 0
