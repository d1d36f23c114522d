"""``doefab reconstruct``: your own dual-pixel captures reconstructed into files other programs open.

Examples:
  doefab reconstruct --task hdr --coded "shots/*_coded.tiff" --uncoded "shots/*_plain.tiff" \\
      --psf out/calibration/psf_pair.npz --crosstalk out/calibration/crosstalk.json --out out/hdr
  doefab reconstruct --task depth --coded a_R.dng b_R.dng --uncoded a_L.dng b_L.dng --out out/depth --tile 384

--coded and --uncoded take files or globs (relative to the working folder), paired in sorted order: the coded
(right, DOE) and plain (left) views of each exposure, as 16-bit colour TIFF, 8-bit PNG, .npy or raw/DNG (binned 2×2
to R, G, B). Each view is scaled to [0, 1] by (DN − black level) / (white level − black level), unmixed with the
calibrated per-column crosstalk (--crosstalk, from doefab calibrate), and reconstructed by the task's network in
overlapping tiles blended with a raised-cosine window, the network told --psf (a measured or fitted PSF pair) instead
of its design's. Every pair is read and checked before anything is written.

Writes, per pair (STEM: the coded file's name without its extension): HDR: OUT/STEM.exr (linear, half float) and
OUT/STEM.png (tone-mapped); spectra: OUT/STEM.hdr + OUT/STEM.img (ENVI, wavelengths in nm) and OUT/STEM.png (sRGB);
depth: OUT/STEM.depth_m.tiff (float32 metres), OUT/STEM.depth_mm.png (16-bit millimetres, clipped at 65.535 m) and
OUT/STEM.png (colour preview). OUT/reconstruct.json records the inputs with their SHA-256, the weights, PSF,
crosstalk, tiling and library versions.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

from doefab.applications import APPLICATIONS
from doefab.cli._args import add_device_arg, number


def register(sub) -> None:
    p = sub.add_parser("reconstruct", help="your own captures to EXR, ENVI, TIFF and PNG files",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", required=True, choices=list(APPLICATIONS), help="the network's task")
    p.add_argument("--coded", required=True, nargs="+", metavar="FILE",
                   help="the coded (right) view of each exposure: files or globs")
    p.add_argument("--uncoded", required=True, nargs="+", metavar="FILE",
                   help="the plain (left) view of each exposure, paired with --coded in sorted order")
    p.add_argument("--psf", default=None, help="psf_pair.npz the network is told (doefab calibrate or diagnose); "
                                               "default: the design's nominal PSFs")
    p.add_argument("--crosstalk", default=None,
                   help="crosstalk.json of the camera (doefab calibrate): the views are unmixed with it; default: "
                        "taken as they are")
    p.add_argument("--weights", "--weights-dir", dest="weights_dir", default=None,
                   help="weights folder (default: the shipped networks)")
    p.add_argument("--variant", default="proposed", choices=["proposed", "coded_only", "uncoded_only"],
                   help="which network of the task")
    p.add_argument("--tile", type=number(int, 64, 8192, unit="pixels; a multiple of 32"), default=None,
                   help="tile side in pixels, what the network sees at once: its memory grows with it (default 512; "
                        "an image narrower than a tile is one tile across)")
    p.add_argument("--overlap", type=number(int, 32, 4096, unit="pixels; a multiple of 32"), default=None,
                   help="pixels shared by neighbouring tiles (default: the PSF kernel rounded up to a multiple of 32)")
    p.add_argument("--black-level", type=number(float, 0, 1e9, unit="DN"), default=None,
                   help="digital number of black, subtracted from every channel (default: a raw file's own, per "
                        "channel, else 0)")
    p.add_argument("--white-level", type=number(float, 0, 1e9, lo_open=True, unit="DN"), default=None,
                   help="digital number of the sensor's clipping level (default: the file's full scale, e.g. 65535 "
                        "for 16 bits, a raw's white level; needed for a 16-bit file whose values stay within 14 "
                        "bits, e.g. 4095 for 12-bit data)")
    p.add_argument("--pixel-format", default="auto", choices=["auto", "npy", "png", "tiff", "raw"],
                   help="how to read the files (auto: by extension)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="replace an earlier reconstruct output in OUT")
    add_device_arg(p)
    p.set_defaults(func=run)


def _pairs(args) -> list[tuple[Path, Path]]:
    """(coded, uncoded) files, each list sorted; one error for unequal counts or two pairs of one name."""
    from doefab.errors import DoefabError
    from doefab.lab.frames import expand

    coded = sorted(expand(args.coded, Path.cwd(), "--coded"))
    uncoded = sorted(expand(args.uncoded, Path.cwd(), "--uncoded"))
    if len(coded) != len(uncoded):
        raise DoefabError(f"--coded matches {len(coded)} files and --uncoded {len(uncoded)}: give one plain view per "
                          f"coded view (they are paired in sorted order)")
    stems = [c.stem for c in coded]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise DoefabError(f"--coded holds several files named {dup[0]}.*: their results would share OUT/{dup[0]}.*; "
                          f"rename them so that each coded file's name (without extension) is unique")
    return list(zip(coded, uncoded))


def _keep_inputs(pairs, out: Path, task: str) -> None:
    """Refuse an --out whose results would replace one of the inputs."""
    from doefab.errors import DoefabError
    from doefab.lab.outputs import result_names

    inputs = {p.resolve() for pair in pairs for p in pair}
    for c, _ in pairs:
        clash = [n for n in result_names(task, c.stem) if (out / n).resolve() in inputs]
        if clash:
            raise DoefabError(f"--out {out} would replace the input {out / clash[0]}: write the results to another "
                              f"folder")


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _versions() -> dict:
    import platform
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in ("doefab", "torch", "numpy", "scipy", "colour-science", "OpenEXR", "spectral", "tifffile", "imageio",
                 "rawpy", "matplotlib"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _psf(args, rec):
    """--psf read and checked against the network (its bands and planes) before any work; None without it."""
    from doefab.errors import DoefabError
    from doefab.optics.psf import PSFPair

    if args.psf is None:
        return None
    pair = PSFPair.load(args.psf)
    try:
        rec._psf(pair)
    except DoefabError as exc:
        raise DoefabError(f"--psf {args.psf}: {exc}; give a pair at every band and plane of the network's design "
                          f"(doefab diagnose writes one: psf_pair_fitted.npz)") from None
    return pair


def _record(args, rec, psf, camera, tile: int, overlap: int) -> dict:
    """reconstruct.json without its pairs: the network, PSF, crosstalk, tiling, levels, library versions and torch's
    thread count."""
    import torch

    return {"task": args.task, "variant": args.variant,
            "weights": {"folder": str(args.weights_dir or "shipped"), "sha256": rec.meta["weights_sha256"],
                        "design_levels_sha256": rec.design_sha256},
            "psf": None if psf is None else {"file": str(args.psf), "sha256": _sha256(args.psf),
                                             "provenance": psf.provenance},
            "crosstalk": None if camera is None else {"file": str(args.crosstalk), "sha256": _sha256(args.crosstalk)},
            "tile_px": tile, "overlap_px": overlap, "black_level_dn": args.black_level,
            "white_level_dn": args.white_level, "pixel_format": args.pixel_format, "versions": _versions(),
            "torch_threads": torch.get_num_threads(),  # HDR's highlight solve rounds differently with another count
            "pairs": []}


def run(args) -> int:
    from doefab.cli._output import claim_output
    from doefab.imaging.crosstalk import DualPixelCrosstalk
    from doefab.io import atomic_write_json
    from doefab.lab.outputs import write_result_rows
    from doefab.lab.capturenotes import clipped_note, small_frame_note, swapped_note
    from doefab.lab.reconstruct import (DEFAULT_TILE, capture_levels, default_overlap, iter_tiled, load_views,
                                        output_channels)
    from doefab.reconstruction.loader import load_reconstructor

    pairs = _pairs(args)
    rec = load_reconstructor(args.task, args.variant, args.weights_dir)
    psf = _psf(args, rec)
    camera = DualPixelCrosstalk.load(args.crosstalk) if args.crosstalk else None
    tile, overlap = args.tile or DEFAULT_TILE, args.overlap or default_overlap(rec, psf)
    out = claim_output(args, "reconstruct", replace=args.force)
    _keep_inputs(pairs, out.path, args.task)
    levels = dict(black_level=args.black_level, white_level=args.white_level, pixel_format=args.pixel_format)
    for c, u in pairs:  # every pair read and checked before anything is written
        load_views(c, u, camera, tile=tile, overlap=overlap, **levels)
    earlier = _earlier_outputs(out.path) if out.existing else set()
    out.create()
    record = _record(args, rec, psf, camera, tile, overlap)
    for c, u in pairs:
        coded, uncoded = load_views(c, u, camera, **levels)
        info: dict = {}
        notes = [n for n in [small_frame_note(rec, coded.shape[1:], psf), clipped_note(coded, uncoded),
                             swapped_note(coded, uncoded, psf or rec.pair)] if n]
        for note in notes:
            print(f"doefab reconstruct: warning: {c.name}: {note}", file=sys.stderr, flush=True)
        rows = iter_tiled(rec, coded, uncoded, tile, overlap, psf=psf, progress=True, info=info)
        files = write_result_rows(args.task, rows, (output_channels(rec), *coded.shape[1:]), out.path, c.stem,
                                  rec.pair.wavelengths, (min(rec.pair.depths), max(rec.pair.depths)))
        used = {v: capture_levels(p, args.black_level, args.white_level, args.pixel_format) for v, p in
                (("coded", c), ("uncoded", u))}
        record["pairs"].append({"coded": str(c), "coded_sha256": _sha256(c), "uncoded": str(u),
                                "uncoded_sha256": _sha256(u), "size_px": [coded.shape[2], coded.shape[1]],
                                "levels_dn": {v: {"black_rgb": b.tolist(), "white": w} for v, (b, w) in used.items()},
                                "files": [f.name for f in files], **info, "warnings": notes})
        print(f"{c.name} + {u.name}: wrote {', '.join(f.name for f in files)}")
    atomic_write_json(out.path / "reconstruct.json", record)
    inputs = {Path(x).resolve() for pair in pairs for x in pair}
    for name in earlier - {f for pair in record["pairs"] for f in pair["files"]}:
        if (out.path / name).resolve() not in inputs:  # an earlier run's result this run did not write again
            (out.path / name).unlink(missing_ok=True)
    print(f"wrote {out.path / 'reconstruct.json'}")
    return 0


def _earlier_outputs(folder: Path) -> set[str]:
    """The result files an earlier reconstruct wrote into ``folder`` (its reconstruct.json's pairs): with --force
    they go unless this run writes them again, so the folder holds one run's results, as its record says."""
    import json

    try:
        record = json.loads((folder / "reconstruct.json").read_text())
        names = {str(f) for pair in record.get("pairs", []) for f in pair.get("files", [])}
    except (OSError, ValueError, AttributeError, TypeError):
        return set()
    return {n for n in names if n and Path(n).name == n}  # plain names in the folder, nothing outside it
