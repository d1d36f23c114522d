"""``doefab psf``: coded/uncoded PSFs of a height map (.npy, metres) for given bands and depths."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from doefab.cli._args import add_device_arg, depth_m, number, wavelength_nm
from doefab.errors import DoefabError
from doefab.optics.camera import PRESETS


def register(sub) -> None:
    p = sub.add_parser("psf", help="compute the split-aperture PSFs of a height map",
                       description=__doc__, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--height", help="height map .npy in metres, (N, N) of the preset's DOE grid (default: blank DOE)")
    p.add_argument("--preset", default="default", choices=list(PRESETS),
                   help="camera preset (sets the DOE grid the height map must match)")
    p.add_argument("--wavelengths-nm", type=wavelength_nm, nargs="+", default=[656, 589, 486],
                   help="wavelengths (nm)")
    p.add_argument("--depths-m", type=depth_m, nargs="+", default=[float("inf")], help="point depths (m); inf ok")
    p.add_argument("--kernel", type=number(int, 1, 8191, unit="sensor pixels"), default=255,
                   help="PSF window K (sensor pixels)")
    p.add_argument("--pupil-oversample", type=number(int, 1, 8, unit="pupil samples per DOE pixel"), default=1,
                   help="pupil samples per DOE pixel (near points or large windows need more)")
    p.add_argument("--route", default="spectral", choices=["spectral", "mft", "fft", "asm"], help="propagation route")
    p.add_argument("--precision", default="float32", choices=["float32", "float64"], help="arithmetic precision")
    add_device_arg(p)
    p.add_argument("--out", required=True, help="output folder (psf.npz and psf.png)")
    p.add_argument("--force", action="store_true", help="replace an earlier psf output in OUT")
    p.set_defaults(func=run)


def _load_height(path: Path, n: int, preset: str) -> np.ndarray:
    if path.is_dir():
        raise DoefabError(f"--height {path} is a folder: pass a .npy file (heights in metres)")
    if not path.is_file():
        raise DoefabError(f"--height {path} not found: pass an existing .npy file (heights in metres)")
    try:
        height = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DoefabError(f"--height {path} is not a readable .npy array ({exc})") from None
    if height.shape != (n, n):
        raise DoefabError(f"--height {path} has shape {height.shape} but the {preset!r} preset's DOE grid is "
                          f"({n}, {n}): resample it or choose the --preset whose grid it was made for")
    return height


def run(args) -> int:
    import doefab
    from doefab.cli._output import claim_output
    from doefab.io import atomic_write_bytes
    from doefab.plotting import psf_pair_figure

    cam = doefab.Camera.preset(args.preset)
    height = _load_height(Path(args.height), cam.doe_pixels, args.preset) if args.height else None
    lams = [w * 1e-9 for w in args.wavelengths_nm]
    plan = doefab.PSFPlan(cam, lams, args.depths_m, args.kernel, route=args.route, precision=args.precision,
                          pupil_oversample=args.pupil_oversample)  # checks sampling before any output exists
    out = claim_output(args, "psf", replace=args.force)
    import torch

    with torch.no_grad():
        pair = plan(height)
    out.create()
    import io

    buf = io.BytesIO()
    np.savez(buf, coded=pair.coded.numpy(), uncoded=pair.uncoded.numpy(), wavelengths_m=np.array(lams),
             depths_m=np.array(args.depths_m), sensor_pitch_m=cam.sensor_pitch)
    atomic_write_bytes(out.path / "psf.npz", buf.getvalue())
    psf_pair_figure(out.path / "psf.png", pair.coded.numpy(), pair.uncoded.numpy(), args.depths_m, cam.sensor_pitch,
                    title=f"PSFs ({', '.join(f'{w:g}' for w in args.wavelengths_nm)} nm summed)")
    for zi, z in enumerate(args.depths_m):
        print(f"z = {_z(z)}: coded energy in window {float(pair.coded[zi].sum()) / len(lams):.4f}, "
              f"uncoded {float(pair.uncoded[zi].sum()) / len(lams):.4f} (mean over bands; 0.5 = all of the half)")
    print(f"wrote {out.path / 'psf.npz'} and {out.path / 'psf.png'}")
    return 0


def _z(z: float) -> str:
    return f"{z:g} m" if math.isfinite(z) else "∞"
