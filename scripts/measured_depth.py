"""Writes doefab/measured/middlebury_depth.npz, the measured depth scenes of the measured-data validation set, from
a copy of the Middlebury Stereo Evaluation v3's quarter-resolution training set (MiddEval3 trainingQ: the 2014
datasets, Scharstein et al., GCPR 2014, https://vision.middlebury.edu/stereo/submit3/; "we grant permission to use
and publish all images and disparity maps on this website", with the request to cite the paper).

    .venv/bin/python scripts/measured_depth.py PATH/TO/ROOT

``ROOT`` holds ``MiddEval3/trainingQ/<scene>/{im0.png, calib.txt}`` and each scene's ``disp0GT.pfm`` there or under
``MiddEval3GT/trainingQ/<scene>/`` (as the copy read, github.com/Homay0118/DDL_demo at 69cc478, lays them out).

For each scene of ``SCENES`` it stores the left image's PNG file as it is (8-bit sRGB), the left view's ground-truth
disparity as a 16-bit PNG in steps of ``1 / DISPARITY_SCALE`` px (rounded: at most 0.002 px, 1e-4 of any depth's
``d + doffs``; 0 where the ground truth has none) and the calibration the depth is computed with
(``Z = f·B / (d + doffs)``: focal length and ``doffs`` in pixels, the baseline in metres); the source files'
SHA-256 go with them (``sources``). Left out: Motorcycle (the measured set takes it from scikit-image), Pipes (its
median depth, 5.2 m, lies beyond the shipped depth design's 5 m), the E, L and P variants (the same scenes under
other exposure, lighting or rectification) and ArtL and Teddy (2005 and 2003 scenes, not of the 2014 rig).
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import sys
from pathlib import Path

import numpy as np

from doefab.io import atomic_write_bytes

SCENES = ("Adirondack", "Jadeplant", "Piano", "Playroom", "Playtable", "Recycle", "Shelves", "Vintage")
DISPARITY_SCALE = 256  # stored steps per pixel of disparity
OUT = Path(__file__).resolve().parents[1] / "doefab" / "measured" / "middlebury_depth.npz"


def calibration(text: str) -> dict:
    """{focal_px, baseline_m, doffs_px} from a MiddEval3 calib.txt (``cam0=[f 0 cx; ...]``, ``doffs=``,
    ``baseline=`` in millimetres)."""
    focal = float(re.search(r"cam0=\[\s*([-\d.eE+]+)", text).group(1))
    doffs = float(re.search(r"doffs=\s*([-\d.eE+]+)", text).group(1))
    baseline_mm = float(re.search(r"baseline=\s*([-\d.eE+]+)", text).group(1))
    return {"focal_px": focal, "baseline_m": baseline_mm / 1000.0, "doffs_px": doffs}


def _files(root: Path, scene: str) -> dict[str, Path]:
    data = root / "MiddEval3" / "trainingQ" / scene
    gt = data / "disp0GT.pfm"
    if not gt.is_file():
        gt = root / "MiddEval3GT" / "trainingQ" / scene / "disp0GT.pfm"
    return {"im0.png": data / "im0.png", "calib.txt": data / "calib.txt", "disp0GT.pfm": gt}


def main(root: str) -> None:
    import imageio.v3 as iio

    root = Path(root)
    arrays, sources = {}, {}
    for scene in SCENES:
        files = _files(root, scene)
        png = files["im0.png"].read_bytes()
        image = np.asarray(iio.imread(png))
        disp = np.asarray(iio.imread(files["disp0GT.pfm"]), np.float64)
        if disp.shape != image.shape[:2] or image.ndim != 3 or image.dtype != np.uint8:
            raise SystemExit(f"{scene}: disparity {disp.shape} and 8-bit image {image.shape} do not match")
        steps = np.where(np.isfinite(disp), np.round(disp * DISPARITY_SCALE), 0.0)
        if steps.max() >= 2**16 or (steps[np.isfinite(disp)] < 1).any():
            raise SystemExit(f"{scene}: disparities outside (0, {2**16 / DISPARITY_SCALE}) px")
        arrays[f"{scene}_image_png"] = np.frombuffer(png, np.uint8)
        arrays[f"{scene}_disparity_png"] = np.frombuffer(iio.imwrite("<bytes>", steps.astype(np.uint16),
                                                                     extension=".png"), np.uint8)
        sources[scene] = {"calibration": calibration(files["calib.txt"].read_text()),
                          "files": {k: {"path": str(p.relative_to(root)),
                                        "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
                                    for k, p in files.items()}}
        c = sources[scene]["calibration"]
        z = c["focal_px"] * c["baseline_m"] / (disp[np.isfinite(disp)] + c["doffs_px"])
        print(scene, image.shape, f"depth {z.min():.2f}–{z.max():.2f} m, ground truth on "
              f"{np.isfinite(disp).mean():.0%}")
    buf = io.BytesIO()
    np.savez(buf, sources=np.array(json.dumps(sources)), disparity_scale=np.array(DISPARITY_SCALE), **arrays)
    atomic_write_bytes(OUT, buf.getvalue())
    print(f"wrote {OUT} ({OUT.stat().st_size / 2**20:.1f} MiB)")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
