"""``doefab demo``: coded and uncoded PSFs of the default camera with a blank DOE and a test grating."""

from __future__ import annotations

import math
import time

import numpy as np

from doefab.cli._args import DefaultsHelp, add_device_arg, number

RGB_M = (656e-9, 589e-9, 486e-9)
GRATING_PERIOD_PX = 16  # the test grating's period, DOE pixels


def _depths(cam) -> tuple:
    """The demo's planes (m): the camera's focus, a star, a nearer point."""
    return cam.focus_distance, math.inf, 2.0


#: the least --kernel (px): the default camera's plain-half blur at the demo's planes and the test grating's window
#: (``min_kernel``; a constant so that building the parser, for --help or any subcommand, does not load torch)
MIN_KERNEL = 149


def min_kernel(cam) -> int:
    """The least PSF window (px) the demo takes on ``cam``: its plain half's blur at the demo's planes with room,
    and the test grating's first orders with their metric boxes. Example: ``min_kernel(Camera()) == MIN_KERNEL``."""
    return max(cam.window_for_blur(_depths(cam)), _grating_window(cam))


def _grating_window(cam) -> int:
    """The window (px) that holds the test grating's (``GRATING_PERIOD_PX``) first order of the demo's longest
    band with its metric box and margin (``GratingTask.window_px``)."""
    from doefab.tasks.grating import GratingTask, grating_spot_px

    return GratingTask().window_px(grating_spot_px(cam, max(RGB_M), GRATING_PERIOD_PX * cam.doe_pitch))


def register(sub) -> None:
    p = sub.add_parser("demo", help="plot the default camera's coded and uncoded PSFs",
                       description=__doc__, formatter_class=DefaultsHelp)
    p.add_argument("--out", default="out/demo", help="output folder (an earlier demo output there is replaced; "
                                                     "any other non-empty folder is refused)")
    p.add_argument("--kernel", type=number(int, MIN_KERNEL, 511, unit="sensor pixels"), default=255,
                   help=f"PSF window K (sensor pixels; ≥ {MIN_KERNEL}: the plain half's blur at 2 m with 2 px of "
                        f"room and the test grating's first orders with their metric boxes)")
    add_device_arg(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import torch
    from tqdm import tqdm

    import doefab
    from doefab.io import atomic_write_json
    from doefab.validate import distance_record
    from doefab.cli._output import claim_output
    from doefab.plotting import plot_height, psf_pair_figure

    claim = claim_output(args, "demo", replace=True)
    cam = doefab.Camera()
    depths = _depths(cam)
    designs = {
        "blank": doefab.blank_height(cam),
        "grating16": doefab.quantize_height(doefab.blazed_grating_height(cam, GRATING_PERIOD_PX), cam),
    }
    plan = doefab.PSFPlan(cam, RGB_M, depths, args.kernel)
    out = claim.create()
    summary = {"camera": cam.to_dict(), "wavelengths_m": list(RGB_M),
               "depths_m": [distance_record(d) for d in depths], "kernel_px": args.kernel,
               "results": {}}
    bar = tqdm(designs.items(), desc="demo PSFs", unit="design")
    for name, height in bar:
        t = time.perf_counter()
        with torch.no_grad():
            pair = plan(height)
        dt = time.perf_counter() - t
        coded, uncoded = pair.coded.numpy(), pair.uncoded.numpy()
        bar.set_postfix(design=name, seconds=f"{dt:.1f}", coded_sum=f"{coded.sum() / coded.shape[0] / 3:.3f}")
        np.save(out / f"{name}_coded.npy", coded)
        np.save(out / f"{name}_uncoded.npy", uncoded)
        psf_pair_figure(out / f"{name}_psfs.png", coded, uncoded, depths, cam.sensor_pitch,
                        title=f"{name}: R+G+B (656, 589, 486 nm)")
        plot_height(out / f"{name}_height.png", height, cam.doe_pitch, f"{name} height map")
        summary["results"][name] = {
            "seconds": round(dt, 3),
            "coded_energy_in_window": coded.sum(axis=(-1, -2)).tolist(),
            "uncoded_energy_in_window": uncoded.sum(axis=(-1, -2)).tolist(),
        }
    atomic_write_json(out / "summary.json", summary)
    print(f"wrote {out}/: *_psfs.png, *_height.png, *_coded.npy, *_uncoded.npy "
          f"[n_depths, n_wavelengths, K, K], summary.json")
    return 0
