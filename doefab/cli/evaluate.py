"""``doefab evaluate``: a task's networks on held-out scenes (the paper's Tables 1–3).

By default under the conditions a real camera makes: captures through fabricated parts drawn from the default
tolerance budget, per-column dual-pixel crosstalk unmixed with a noisy calibration, depth between the network's
planes — while the networks are told the nominal PSF. --clean evaluates on the nominal model's own captures.
--split val is for choices (designs, settings); the test split is for the tables; --split final reads the final
test set (new scenes and parts from the test split's content, made after every earlier test read), and each such
read is appended to OUT/final_split_reads.md; --split real is the measured-data validation set (HDR radiance
maps, a measured depth map, light of a measured family no split holds: doefab.reconstruction.realdata). Hyperspectral results are also given for in-library and
out-of-library light. Torch runs on one thread while it evaluates, so the numbers do not depend on the machine's.

--psf FILE (a psf_pair.npz of doefab calibrate or diagnose): the networks are told that pair — a fabricated part's
— and the scenes are captured through the same pair (the measured part is the truth), with the camera's crosstalk
unless --clean; --capture-psf FILE captures them through another pair instead (e.g. diagnose's
psf_pair_fitted.npz; alone, the networks are told their nominal pair). A pair whose bands, depth planes or sensor
pitch differ from the networks' design is refused.

Writes OUT/metrics.json (every variant's mean metrics, the thread count, library versions, code version, each
weights file's SHA-256 and, with --psf, each pair's file, SHA-256 and provenance) and OUT/examples.png.
"""

from __future__ import annotations


from doefab.applications import APPLICATIONS
from doefab.cli._args import DefaultsHelp, add_device_arg, add_sensor_args, number
from doefab.io import json_text


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="score reconstruction networks on held-out test scenes",
                       description=__doc__, formatter_class=DefaultsHelp)
    p.add_argument("--task", required=True, choices=list(APPLICATIONS), help="task")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--images", type=number(int, 1, 10_000), default=16, help="test scenes")
    p.add_argument("--size", type=number(int, 64, 2048, unit="pixels; a multiple of 32"), default=256,
                   help="test image side in pixels")
    p.add_argument("--weights-dir", default=None, help="weights folder (default: the shipped ones)")
    p.add_argument("--design", default=None, help="evaluate networks trained for this design folder (with --weights-dir)")
    p.add_argument("--variants", default="proposed,coded_only,uncoded_only",
                   help="comma-separated variants to evaluate (default: all three)")
    p.add_argument("--clean", action="store_true",
                   help="the nominal model's own captures (no fabricated part, crosstalk or off-plane depth; with "
                        "--psf: that pair's, without crosstalk)")
    p.add_argument("--split", default="test", choices=["test", "val", "final", "real"],
                   help="held-out scenes: val for choices, test for the tables, final for the final test set (each "
                        "read logged in OUT/final_split_reads.md), real for the measured-data validation set")
    p.add_argument("--psf", default=None, metavar="FILE",
                   help="a psf_pair.npz (doefab calibrate / diagnose): the networks are told it and the scenes are "
                        "captured through it")
    p.add_argument("--capture-psf", default=None, metavar="FILE",
                   help="capture the scenes through this psf_pair.npz instead (e.g. a fitted model)")
    p.add_argument("--crosstalk", default=None, metavar="FILE",
                   help="with --psf or --capture-psf: the camera's measured crosstalk.json (doefab calibrate) mixes "
                        "and unmixes the views instead of the budget's sensor")
    add_sensor_args(p)
    add_device_arg(p)
    p.add_argument("--force", action="store_true", help="replace an earlier evaluation in OUT")
    p.set_defaults(func=run)


def run(args) -> int:
    from doefab.cli._args import sensor_arg, task_design_arg
    from doefab.cli._output import claim_output
    from doefab.errors import DoefabError
    from doefab.reconstruction.evaluate import FINAL_LEDGER, evaluate
    from doefab.reconstruction.loader import load_reconstructor

    if args.size % 32:
        raise DoefabError(f"--size {args.size} must be a multiple of 32 (e.g. 256)")
    design = task_design_arg(args, need_weights_dir=True)
    variants = tuple(v.strip() for v in args.variants.split(",") if v.strip())
    bad = [v for v in variants if v not in ("proposed", "coded_only", "uncoded_only")]
    if bad or not variants:
        raise DoefabError(f"--variants: unknown {bad or 'empty list'}; choose from proposed, coded_only, uncoded_only")
    sensor = sensor_arg(args, design)
    told, told_rec = read_psf_arg(args.psf, "--psf")
    capture, capture_rec = read_psf_arg(args.capture_psf, "--capture-psf")
    camera = read_crosstalk_arg(args, told is not None or capture is not None)
    out = claim_output(args, "evaluate", replace=args.force,  # --out checked before the networks' PSFs
                       keep_on_failure=lambda: (args.outdir.path / FINAL_LEDGER).is_file())  # a read is a read
    if args.split == "final":
        args.resume_hint = f"this read of the final test set is logged in {out.path / FINAL_LEDGER}, which is kept"
    for v in variants:  # a bad weights file, or one for another sensor, or a pair they cannot take: refused first
        rec = load_reconstructor(args.task, v, args.weights_dir, design, sensor=sensor)
    check_psf_args(args.task, rec.pair, told, capture)
    if args.split == "real":  # a scene larger than the measured maps: refused before the parts are made
        from doefab.reconstruction.realdata import check_side

        check_side(args.task, args.size, rec.pair.coded.shape[-1] // 2)
    out.create()
    cond = _conditions(args, design, capture if capture is not None else told, camera)
    records = {"told": told_rec or "the design's nominal pair", "captured_through": capture_rec or told_rec}
    res = evaluate(args.task, out.path, args.images, args.size, args.weights_dir, design=design, variants=variants,
                   conditions=cond, split=args.split, sensor=sensor, psf=told, capture_psf=capture,
                   psf_records=None if told is None and capture is None else records)
    print(json_text({"rows": res["rows"], **({"by_light": res["by_light"]} if "by_light" in res else {})}, indent=1))
    print(f"wrote {out.path / 'metrics.json'} and {out.path / 'examples.png'}")
    if args.split == "final":
        print(f"this read of the final test set is logged in {out.path / FINAL_LEDGER}")
    return 0


def _conditions(args, design, part, camera=None):
    """The split's capture conditions: through ``part`` (a given pair) with the camera's crosstalk (``camera``: the
    measured one of --crosstalk, else the budget's), or the honest ones (fabricated parts from the budget); None
    with --clean (through ``part`` or the nominal pair, no crosstalk)."""
    from doefab.reconstruction.evaluate import one_thread
    from doefab.tolerance.conditions import for_splits, measured

    if args.clean:
        return None
    if part is not None:
        return measured(part, args.split, camera=camera)
    with one_thread():  # the fabricated parts computed (and cached) here: on one thread, as the evaluation runs
        return for_splits(args.task, design, "honest", (args.split,), progress=True)[args.split]


def read_crosstalk_arg(args, with_part: bool):
    """The measured camera (``DualPixelCrosstalk``) of ``--crosstalk``, read and checked before any work; None
    when the flag is not given. It goes with a measured part (``with_part``) and with the camera's crosstalk (not
    --clean)."""
    from doefab.errors import DoefabError
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    if args.crosstalk is None:
        return None
    if getattr(args, "clean", False):
        raise DoefabError("--crosstalk gives the camera's crosstalk and --clean leaves it out: give one of them")
    if not with_part:
        raise DoefabError("--crosstalk is the measured camera's: give its part too (--psf psf_pair.npz from the "
                          "same camera's doefab calibrate)")
    return DualPixelCrosstalk.load(args.crosstalk)


def read_psf_arg(path, flag: str):
    """(PSFPair, its record: file, SHA-256, provenance...) of a ``psf_pair.npz`` flag, read and checked before any
    work; (None, None) when the flag is not given."""
    from doefab.errors import DoefabError
    from doefab.optics.psf import PSFPair
    from doefab.reconstruction.partfinetune import pair_record

    if path is None:
        return None, None
    try:
        pair = PSFPair.load(path)
    except DoefabError as exc:
        raise DoefabError(f"{flag}: {exc}") from None
    return pair, pair_record(pair, path)


def check_psf_args(task: str, network_pair, told, capture) -> None:
    """Refuse, before any output, a --psf pair the networks cannot be told or a --capture-psf of another camera."""
    from doefab.reconstruction.partfinetune import check_capture, fit_to_network

    if told is not None:
        fit_to_network(told, network_pair, task, "--psf")
    if capture is not None:
        check_capture(capture, network_pair, "--capture-psf")
