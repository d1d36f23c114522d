"""``doefab psf``: coded/uncoded PSFs of a height map (.npy, metres) for given bands and depths."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError


def register(sub) -> None:
    p = sub.add_parser("psf", help="compute the split-aperture PSFs of a height map",
                       description=__doc__, formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--height", help="height map .npy in metres, (N, N) of the camera grid (default: blank DOE)")
    p.add_argument("--preset", default="default", help="camera preset: default, hdr, hyperspectral, depth")
    p.add_argument("--wavelengths-nm", type=float, nargs="+", default=[656, 589, 486], help="wavelengths (nm)")
    p.add_argument("--depths-m", type=float, nargs="+", default=[float("inf")], help="point depths (m); inf ok")
    p.add_argument("--kernel", type=int, default=255, help="PSF window K (sensor pixels)")
    p.add_argument("--route", default="spectral", help="spectral, mft, fft or asm")
    p.add_argument("--precision", default="float32", help="float32 or float64")
    p.add_argument("--out", required=True, help="output folder (psf.npz and psf.png)")
    p.set_defaults(func=run)


def run(args) -> int:
    import torch

    import doefab
    from doefab.io import atomic_write_bytes
    from doefab.plotting import plot_psf_grid

    cam = doefab.Camera.preset(args.preset)
    height = None
    if args.height:
        path = Path(args.height)
        if not path.is_file():
            raise DoefabError(f"height map {path} not found: pass an existing .npy file (metres)")
        try:
            height = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise DoefabError(f"cannot read {path} as a .npy array ({exc})") from None
    lams = [w * 1e-9 for w in args.wavelengths_nm]
    with torch.no_grad():
        pair = doefab.split_aperture_psf(height, cam, lams, args.depths_m, args.kernel, route=args.route,
                                         precision=args.precision)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import io

    buf = io.BytesIO()
    np.savez(buf, coded=pair.coded.numpy(), uncoded=pair.uncoded.numpy(), wavelengths_m=np.array(lams),
             depths_m=np.array(args.depths_m), sensor_pitch_m=cam.sensor_pitch)
    atomic_write_bytes(out / "psf.npz", buf.getvalue())
    panels = []
    for zi, z in enumerate(args.depths_m):
        for half in ("coded", "uncoded"):
            panels.append((f"{half}, z = {z:g} m", pair[half][zi].sum(0).numpy()))
    plot_psf_grid(out / "psf.png", panels, cam.sensor_pitch, ncols=2)
    for zi, z in enumerate(args.depths_m):
        print(f"z = {z:g} m: coded energy in window {float(pair.coded[zi].sum()) / len(lams):.4f}, "
              f"uncoded {float(pair.uncoded[zi].sum()) / len(lams):.4f} (mean over bands; 0.5 = all of the half)")
    print(f"wrote {out / 'psf.npz'} and {out / 'psf.png'}")
    return 0
