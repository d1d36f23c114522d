"""``doefab psf``: coded/uncoded PSFs of a height map (.npy, metres) for given bands and depths.

The camera: a preset (--preset), a scene file's (--scene: its camera, bands, depth planes, window and device key;
the scene must pass the checks doefab run makes, as written) or a design's (--design: a design folder or mask set,
its L-level DOE on the camera, bands, depth planes and window it was designed for). --wavelengths-nm, --depths-m
and --kernel then replace any of these.

  doefab psf --design masks/streak --out out/psf_streak
  doefab psf --scene scenes/my_camera.toml --height my_doe.npy --out out/psf_mine
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from doefab.cli._args import DefaultsHelp, add_device_arg, depth_m, number, wavelength_nm
from doefab.errors import DoefabError
from doefab.optics.camera import PRESETS


class _Help(argparse.RawDescriptionHelpFormatter, DefaultsHelp):
    """The description as written (its examples on their own lines), and each flag's default where it has one."""

    def _get_help_string(self, action):
        return action.help if action.default is None else super()._get_help_string(action)


def register(sub) -> None:
    from doefab.pipeline.scenekeys import keys_of

    p = sub.add_parser("psf", help="compute the split-aperture PSFs of a height map",
                       description=__doc__, formatter_class=_Help)
    p.add_argument("--height", help="height map .npy in metres, (N, N) of the camera's DOE grid (default: blank DOE)")
    camera = p.add_mutually_exclusive_group()
    camera.add_argument("--preset", default=None, choices=list(PRESETS),
                        help="camera preset (sets the DOE grid the height map must match; default: 'default')")
    camera.add_argument("--scene", metavar="FILE", default=None,
                        help="a scene file (.toml): its camera, bands, depth planes and PSF window")
    camera.add_argument("--design", metavar="DIR", default=None,
                        help="a design folder, mask set or shipped design's name (streak, grating, half-ring): "
                             "its L-level DOE, camera, bands, depth planes and window")
    p.add_argument("--wavelengths-nm", type=wavelength_nm, nargs="+", default=None,
                   help="wavelengths (nm; default: the scene's or design's, else 656 589 486)")
    p.add_argument("--depths-m", type=depth_m, nargs="+", default=None,
                   help="point depths (m; inf ok; default: the scene's or design's, else inf)")
    window = keys_of("optics")["kernel_px"]  # the scene key's range, in one place
    p.add_argument("--kernel", type=number(int, int(window.lo), int(window.hi), unit="sensor pixels"), default=None,
                   help=f"PSF window K (sensor pixels, {window.lo:g}–{window.hi:g}; default: the scene's or "
                        f"design's, else 255)")
    p.add_argument("--pupil-oversample", type=number(int, 1, 8, unit="pupil samples per DOE pixel"), default=1,
                   help="pupil samples per DOE pixel (near points or large windows need more)")
    p.add_argument("--route", default="spectral", choices=["spectral", "mft", "fft", "asm"], help="propagation route")
    p.add_argument("--precision", default="float32", choices=["float32", "float64"], help="arithmetic precision")
    add_device_arg(p, scene=True)
    p.add_argument("--out", required=True, help="output folder (psf.npz and psf.png)")
    p.add_argument("--force", action="store_true", help="replace an earlier psf output in OUT")
    p.set_defaults(func=run)


def _load_height(path: Path, n: int, source: str) -> np.ndarray:
    if path.is_dir():
        raise DoefabError(f"--height {path} is a folder: pass a .npy file (heights in metres)")
    if not path.is_file():
        raise DoefabError(f"--height {path} not found: pass an existing .npy file (heights in metres)")
    try:
        height = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DoefabError(f"--height {path} is not a readable .npy array ({exc})") from None
    if height.shape != (n, n):
        raise DoefabError(f"--height {path} has shape {height.shape} but {source}'s DOE grid is ({n}, {n}): resample "
                          f"it or choose the camera (--preset or --scene) whose grid it was made for")
    return height


def _source(args):
    """(camera, height or None, wavelengths m, depths m, kernel px, the scene's device key or None) from --preset,
    --scene or --design, the band, depth and window flags replacing theirs."""
    from doefab.optics.camera import Camera

    if args.design:
        from doefab.cli._args import design_folder

        if args.height:
            raise DoefabError("--height and --design both give the DOE: drop one (--design uses the design's "
                              "L-level height map)")
        _, d = design_folder(args.design)
        cam, height, what, device, notes = d.camera, d.quantized_height, f"the design {args.design}", None, []
        lams, depths, kernel = d.wavelengths, d.depths, d.kernel_size
    elif args.scene:
        from doefab.pipeline.scene import load_scene
        from doefab.pipeline.system import resolve

        scene = load_scene(args.scene)
        rs = resolve(scene)  # every problem doefab run would refuse, before any work
        notes = [n for n in rs.warnings if n not in rs.stage_warnings]  # the optical system's, not the run's
        cam, height, what, device = rs.camera, None, f"the scene {args.scene}", scene.device
        lams, depths, kernel = rs.task.wavelengths(cam), rs.task.depths(cam), rs.task.kernel_size
    else:
        preset = args.preset or "default"
        cam, height, what, device, notes = Camera.preset(preset), None, f"the {preset!r} preset", None, []
        lams, depths, kernel = [w * 1e-9 for w in (656, 589, 486)], [math.inf], 255
    if args.height:
        height = _load_height(Path(args.height), cam.doe_pixels, what)
    if args.wavelengths_nm is not None:
        from doefab.optics.materials import fit_range_warning

        # the warning for the bands used, not the scene's: outside the substrate's fitted dispersion the index
        # is extrapolated
        notes = [n for n in notes if n != fit_range_warning(cam.material, lams)]
        lams = [w * 1e-9 for w in args.wavelengths_nm]
        notes += [n for n in [fit_range_warning(cam.material, lams)] if n]
    for note in notes:
        print(f"warning: {note}")
    depths = list(args.depths_m) if args.depths_m is not None else [float(z) for z in depths]
    return cam, height, [float(w) for w in lams], depths, int(args.kernel or kernel), device


def run(args) -> int:
    import doefab
    from doefab._devices import using_device
    from doefab.cli._output import claim_output
    from doefab.io import atomic_write_bytes
    from doefab.plotting import psf_pair_figure

    cam, height, lams, depths, kernel, scene_device = _source(args)
    with using_device(scene_device if args.device is None else None, "scene"):  # --device, else the scene's key
        plan = doefab.PSFPlan(cam, lams, depths, kernel, route=args.route, precision=args.precision,
                              pupil_oversample=args.pupil_oversample)  # checks sampling before any output exists
        out = claim_output(args, "psf", replace=args.force)
        import torch

        with torch.no_grad():
            pair = plan(height)
    out.create()
    import io

    buf = io.BytesIO()
    np.savez(buf, coded=pair.coded.numpy(), uncoded=pair.uncoded.numpy(), wavelengths_m=np.array(lams),
             depths_m=np.array(depths), sensor_pitch_m=cam.sensor_pitch)
    atomic_write_bytes(out.path / "psf.npz", buf.getvalue())
    psf_pair_figure(out.path / "psf.png", pair.coded.numpy(), pair.uncoded.numpy(), depths, cam.sensor_pitch,
                    title=f"PSFs ({_bands(lams)} nm summed)")
    for zi, z in enumerate(depths):
        print(f"z = {_z(z)}: coded energy in window {float(pair.coded[zi].sum()) / len(lams):.4f}, "
              f"uncoded {float(pair.uncoded[zi].sum()) / len(lams):.4f} (mean over bands; 0.5 = all of the half)")
    print(f"wrote {out.path / 'psf.npz'} and {out.path / 'psf.png'}")
    return 0


def _bands(lams) -> str:
    nm = [round(w * 1e9, 3) for w in lams]
    return ", ".join(f"{w:g}" for w in nm) if len(nm) <= 6 else f"{len(nm)} bands {min(nm):g}–{max(nm):g}"


def _z(z: float) -> str:
    return f"{z:g} m" if math.isfinite(z) else "∞"
