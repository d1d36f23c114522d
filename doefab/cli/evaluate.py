"""``doefab evaluate``: a task's networks on held-out scenes (the paper's Tables 1–3).

By default under the conditions a real camera makes: captures through fabricated parts drawn from the default
tolerance budget, per-column dual-pixel crosstalk unmixed with a noisy calibration, depth between the network's
planes — while the networks are told the nominal PSF. --clean evaluates on the nominal model's own captures.
--split val is for choices (designs, settings); the test split is for the tables; --split final reads the final
test set (new scenes and parts from the test split's content, made after every earlier test read), and each such
read is appended to OUT/final_split_reads.md. Hyperspectral results are also given for in-library and
out-of-library light. Torch runs on one thread while it evaluates, so the numbers do not depend on the machine's.

Writes OUT/metrics.json (every variant's mean metrics, the thread count, library versions, code version and each
weights file's SHA-256) and OUT/examples.png.
"""

from __future__ import annotations

import argparse
import json

from doefab.cli._args import add_device_arg, add_sensor_args, number


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="score reconstruction networks on held-out test scenes",
                       description=__doc__, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--task", required=True, choices=["hdr", "hyperspectral", "depth"], help="task")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--images", type=number(int, 1, 10_000), default=16, help="test scenes")
    p.add_argument("--size", type=number(int, 64, 2048, unit="pixels; a multiple of 32"), default=256,
                   help="test image side in pixels")
    p.add_argument("--weights-dir", default=None, help="weights folder (default: the shipped ones)")
    p.add_argument("--design", default=None, help="evaluate networks trained for this design folder (with --weights-dir)")
    p.add_argument("--variants", default="proposed,coded_only,uncoded_only",
                   help="comma-separated variants to evaluate (default: all three)")
    p.add_argument("--clean", action="store_true",
                   help="the nominal model's own captures (no fabricated part, crosstalk or off-plane depth)")
    p.add_argument("--split", default="test", choices=["test", "val", "final"],
                   help="held-out scenes: val for choices, test for the tables, final for the final test set (each "
                        "read logged in OUT/final_split_reads.md)")
    add_sensor_args(p)
    add_device_arg(p)
    p.add_argument("--force", action="store_true", help="replace an earlier evaluation in OUT")
    p.set_defaults(func=run)


def run(args) -> int:
    from doefab.cli._args import sensor_arg, task_design_arg
    from doefab.cli._output import claim_output
    from doefab.errors import DoefabError
    from doefab.reconstruction.evaluate import FINAL_LEDGER, evaluate, one_thread
    from doefab.reconstruction.loader import load_reconstructor

    if args.size % 32:
        raise DoefabError(f"--size {args.size} must be a multiple of 32 (e.g. 256)")
    design = task_design_arg(args, need_weights_dir=True)
    variants = tuple(v.strip() for v in args.variants.split(",") if v.strip())
    bad = [v for v in variants if v not in ("proposed", "coded_only", "uncoded_only")]
    if bad or not variants:
        raise DoefabError(f"--variants: unknown {bad or 'empty list'}; choose from proposed, coded_only, uncoded_only")
    sensor = sensor_arg(args, design)
    out = claim_output(args, "evaluate", replace=args.force)  # --out checked before the networks' PSFs
    for v in variants:  # a bad weights file, or one for another sensor, is refused before any output
        load_reconstructor(args.task, v, args.weights_dir, design, sensor=sensor)
    out.create()
    from doefab.tolerance.conditions import for_splits

    with one_thread():  # the fabricated parts computed (and cached) here: on one thread, as the evaluation runs
        cond = for_splits(args.task, design, "clean" if args.clean else "honest", (args.split,), progress=True)
    res = evaluate(args.task, out.path, args.images, args.size, args.weights_dir, design=design, variants=variants,
                   conditions=None if args.clean else cond[args.split], split=args.split, sensor=sensor)
    print(json.dumps({"rows": res["rows"], **({"by_light": res["by_light"]} if "by_light" in res else {})}, indent=1))
    print(f"wrote {out.path / 'metrics.json'} and {out.path / 'examples.png'}")
    if args.split == "final":
        print(f"this read of the final test set is logged in {out.path / FINAL_LEDGER}")
    return 0
