"""``doefab calibrate``: a fabricated part's PSFs and the camera's crosstalk from the lab's own recordings.

Examples:
  doefab calibrate lab/recordings.toml --out out/calibration
  doefab calibrate lab/recordings.toml --design masks/streak --out out/calibration --force

RECORDINGS.toml lists the point-source recordings ([[psf]]: half, view, depth_m, wavelength_nm or channels =
"rgb", frames, dark) and the white-wall pairs ([[wall]]: half, coded_view, plain_view, dark); paths are relative
to it. Every frame is checked before any work. Writes OUT/psf_pair.npz (the measured PSF pair: doefab.PSFPair.load;
every command's --psf), OUT/crosstalk.json (with [[wall]] pairs: per-column crosstalk ratios with standard errors:
doefab.DualPixelCrosstalk.load) and OUT/calibration.html (measured against nominal PSFs, residuals, encircled
energy, the crosstalk profile, photons and signal-to-noise per recording).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from doefab.cli._args import add_device_arg


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="a fabricated part's PSFs and crosstalk from lab recordings",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recordings", metavar="RECORDINGS.toml", help="the recordings file (see doefab calibrate --help)")
    p.add_argument("--design", default=None,
                   help="the design folder (or mask set, or shipped design's name) the part was made from; "
                        "default: the file's design key")
    p.add_argument("--out", required=True, help="output folder (psf_pair.npz, crosstalk.json, calibration.html)")
    p.add_argument("--force", action="store_true", help="replace an earlier calibrate output in OUT")
    add_device_arg(p)
    p.set_defaults(func=run)


# what doefab calibrate writes; --force removes an earlier run's that this run does not write (its crosstalk.json
# beside a new PSF pair without [[wall]] pairs would read as this calibration's)
CALIBRATE_FILES = frozenset({"psf_pair.npz", "crosstalk.json", "calibration.html"})


def run(args) -> int:
    from doefab.cli._output import claim_output
    from doefab.lab.calibrate import measure_recordings, write_calibration
    from doefab.lab.recordings import load_recordings

    rec = load_recordings(args.recordings, design=args.design)  # the schema, before any work
    out = claim_output(args, "calibrate", replace=args.force)  # --out, before any work
    cal = measure_recordings(rec, progress=True)  # every frame checked before anything is written
    out.create()
    summary = write_calibration(cal, out.path)
    written = {Path(f).name for f in summary["files"]}
    for name in CALIBRATE_FILES - written:  # an earlier calibration's (a folder of calibrate's own: claim_output)
        (out.path / name).unlink(missing_ok=True)
    for row in summary["recordings"]:
        snr = "∞" if row["snr"] is None or math.isinf(row["snr"]) else f"{row['snr']:.3g}"
        photons = ("" if row["photons"] is None else
                   f", {row['photons']:.3g} ± {100 * row['photons_rel_se']:.0f} % photons")
        print(f"{row['recording']} ({row['half']}): signal {row['signal_dn']:.4g} DN{photons}, SNR {snr}")
    if "crosstalk" in summary:
        c = summary["crosstalk"]
        print(f"crosstalk (column means): α l→r = {c['alpha_lr']:.4f}, α r→l = {c['alpha_rl']:.4f}")
    print(f"wrote {', '.join(summary['files'])}")
    for w in summary["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    return 0
