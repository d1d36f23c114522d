"""``doefab tolerance``: fabrication and mounting tolerance of a design or mask set: what its parts deliver and
what fraction meets the spec.

Examples:
  doefab tolerance --design masks/grating --samples 300 --out out/tol/grating
  doefab tolerance --design masks/grating --samples 40 --surrogate --sweep --levels --out out/tol/g
  doefab tolerance --design masks/half-ring --samples 24 --networks --out out/tol/depth
  doefab tolerance --design masks/streak --budget my_budget.toml --samples 200 --scheduler local:2 --out out/tol/s

Writes OUT/tolerance.json (every part's errors and metrics; means with 95 % intervals; yield against the
budget's [spec.<task>] with its Wilson interval), OUT/report.md (opening with what the part delivers, its
yield, what limits it and what would buy the most) and figures. The grid each error needs is measured on the
design (--grid auto). Parts are checkpointed as they finish (the Monte Carlo's in OUT/samples.jsonl, the other
studies' in OUT/steps/): rerun with --resume to continue.
"""

from __future__ import annotations

import argparse
import sys

from doefab.cli._args import add_device_arg, number
from doefab.tolerance.schedulers import MAX_WORKERS


def register(sub) -> None:
    p = sub.add_parser("tolerance", help="yield of fabricated and mounted parts (Monte Carlo)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--design", required=True, help="a design folder, a mask set (its design/ is used), or a shipped "
                                                      "design's name (streak, grating, half-ring)")
    p.add_argument("--budget", default=None,
                   help="tolerance budget TOML, or default (the shipped one for the prototype, also when left out)")
    p.add_argument("--holder", default=None,
                   help="a built holder (holder.json or its folder): its clearances and DOE-to-glass distance "
                        "replace the budget's [mounting] decenter, rotation and axial gap")
    p.add_argument("--samples", type=number(int, 0, 100_000), default=20, help="Monte Carlo samples (0 = none)")
    p.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0, help="random seed")
    p.add_argument("--grid", type=_grid, default="auto",
                   help="simulation grid: auto (the coarsest each error needs, measured on the design) or a "
                        "refinement per DOE pixel, 1–8")
    p.add_argument("--sweep", action="store_true", help="one-at-a-time sweeps of every error kind")
    p.add_argument("--levels", action="store_true",
                   help="quantization study: continuous, the design's levels and every fab level count below them "
                        "(16, 8, 4, 2 for a 16-level design)")
    p.add_argument("--networks", action="store_true",
                   help="judge every part through the task's reconstruction network: delivered quality and its "
                        "yield (nominal and measured PSF)")
    p.add_argument("--weights-dir", default=None, help="networks trained for this design (default: the shipped ones)")
    p.add_argument("--surrogate", action="store_true",
                   help="also a sensitivity surrogate: fitted on simulated parts, calibrated on 16 of its own, "
                        "Monte Carlo on it, and its yield minus the direct judgement's on parts it never saw (the "
                        "direct Monte Carlo's when there are at least 16), with a 95 %% interval")
    p.add_argument("--workers", type=_workers, default=None,
                   help=f"local worker processes, 1–{MAX_WORKERS}, or auto (default: one per core when there are "
                        "at least 4 parts per core, else in process)")
    p.add_argument("--scheduler", type=scheduler_arg, default=None,
                   help=f"Dask: local:N (a LocalCluster of N = 1..{MAX_WORKERS} workers; one GPU each on a CUDA "
                        "--device) or tcp://HOST:PORT")
    add_device_arg(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--resume", action="store_true",
                   help="continue the study in OUT with the parts and steps it finished")
    p.add_argument("--force", action="store_true", help="replace an earlier tolerance study in OUT")
    p.set_defaults(func=run)


def _grid(text: str):
    if text == "auto":
        return text
    return number(int, 1, 8, unit="cells per DOE pixel", hint=" (or auto)")(text)


def _workers(text: str):
    if text == "auto":
        return None
    return number(int, 1, MAX_WORKERS, unit="processes", hint=" (or auto)")(text)


def scheduler_arg(text: str) -> str:
    """``local:N`` or ``tcp://HOST:PORT`` (``tolerance.schedulers.parse_scheduler``), checked when the flag is
    parsed."""
    from doefab.errors import DoefabError
    from doefab.tolerance.schedulers import parse_scheduler

    try:
        parse_scheduler(text)
    except DoefabError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _check_network(design_task: str, ddir, weights_dir) -> dict:
    """The record of the proposed network the network-level study judges through: one for the design's application,
    trained for this design (``loader.weights_record``; its PSFs are computed only once the study runs)."""
    from doefab.applications import of_design
    from doefab.errors import DoefabError
    from doefab.reconstruction.loader import weights_record

    app = of_design(design_task)
    if app is None:
        raise DoefabError(f"--networks: no reconstruction network judges a {design_task} design; drop --networks "
                          f"for the PSF-level study")
    return weights_record(app.name, "proposed", weights_dir, ddir)


def _calibration_notes(budget: dict, record: dict | None) -> list[str]:
    """The budget's crosstalk calibration where its noise swamps the sensor's changes (``calibration_warning``):
    with the budget's sensor noise (the PSF-level judge's) and, for a network-level study, the noise of the sensor
    the network was trained for (its captures')."""
    import copy

    from doefab.imaging.sensor import sensor_from_record
    from doefab.tolerance.errors import calibration_warning, with_sensor_noise

    budgets = [budget] + ([with_sensor_noise(copy.deepcopy(budget), sensor_from_record(record.get("sensor")))]
                          if record is not None else [])
    return list(dict.fromkeys(n for n in map(calibration_warning, budgets) if n))


def run(args) -> int:
    from pathlib import Path

    from doefab.cli._args import design_folder
    from doefab.cli._output import claim_output, resume_hint
    from doefab.errors import DoefabError
    from doefab.tolerance.errors import holder_mounting, load_budget, names_default_budget
    from doefab.tolerance.report import STEPS, run_study
    from doefab.tolerance.schedulers import check_reachable, runner_conflict

    ddir, design = design_folder(args.design)  # validated before any output exists
    if args.weights_dir is not None and not args.networks:
        raise DoefabError("--weights-dir is read only by the network-level study: add --networks, or drop "
                          "--weights-dir")
    record = None
    if args.networks:  # the judge's network, checked before any output exists or any part is judged
        record = _check_network(design.task, ddir, args.weights_dir)
    if names_default_budget(args.budget):
        args.budget = None  # the shipped budget by its name, as a scene's tolerance.budget = "default" names it
    budget = load_budget(args.budget)
    if args.holder:
        budget.setdefault("mounting", {}).update(holder_mounting(args.holder))
    for note in _calibration_notes(budget, record):
        print(f"warning: {note}", file=sys.stderr)
    if args.resume and args.force:
        raise DoefabError("--resume continues a study and --force starts one afresh: give one of them")
    both = runner_conflict(args.workers, args.scheduler, ("--workers", "--scheduler"))
    if both:
        raise DoefabError(both)
    check_reachable(args.scheduler, "--scheduler")
    saved = ("samples.jsonl", STEPS)  # a study's progress, which --resume continues and a failed run keeps
    if args.resume and not any((Path(args.out) / f).exists() for f in saved):
        raise DoefabError(f"--resume: {args.out} holds no tolerance study to continue (no samples.jsonl, no "
                          f"{STEPS}/): start one without --resume")
    out = claim_output(args, "tolerance", replace=args.force or args.resume, replace_flag="--force (or --resume)",
                       keep_on_failure=lambda: any((args.outdir.path / f).exists() for f in saved))
    args.resume_hint = resume_hint(f"the parts and steps it finished are kept in {out.path}", args.force)
    out.create()
    res = run_study(ddir, budget, out.path, samples=args.samples, seed=args.seed, grid=args.grid,
                    do_sweep=args.sweep, do_levels=args.levels, workers=args.workers, scheduler=args.scheduler,
                    budget_path=(args.budget or "doefab/tolerance/budget.toml (default)")
                    + (f", [mounting] from {args.holder}" if args.holder else ""), networks=args.networks,
                    surrogate=args.surrogate, weights_dir=args.weights_dir, fresh=args.force)
    from doefab.tolerance.report import summary_lines

    for line in summary_lines(res):
        print(line.replace("**", ""))
    print(f"wrote {out.path / 'tolerance.json'} and {out.path / 'report.md'}")
    return 0
