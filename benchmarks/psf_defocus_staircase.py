"""How far a structured DOE's PSF is off at a defocused plane, against the defocus phase step per DOE pixel.

A pupil sampled once per DOE pixel (``pupil_oversample`` q = 1) holds the point source's smooth wavefront constant
over each pixel, and a structured height map's PSF takes the flat pixel's envelope: the wavefront's tilt inside a
pixel is lost. For a quadratic defocus whose phase changes by Δφ between neighbouring pixels at the pupil's rim,
the light a pixel sends along its tilt is damped by sinc(Δφ_r / 2π) with Δφ_r = Δφ r / R at radius r, which on a
uniformly lit disc gives (the sinc's second order)

- a lost fraction of the coded light of about Δφ² / 24, and
- a relative L2 error of the PSF of about Δφ² / (12 √3) = 0.048 Δφ².

This script measures both against the q → ∞ limit (Richardson extrapolation of q = 2 and 4, the error falling as
1 / q²) on the 8.64 mm aperture at 512 DOE pixels (16.9 µm), 486 nm, focused at 3.5 m, with the point placed so that
the step ``doefab.pipeline.sampling.source_phase_step`` reports (what ``doefab doctor`` prints) takes each value
asked; two coded DOEs: the half-ring's Fresnel start and a random 16-level map in 4 × 4-pixel blocks (whose scatter
partly leaves the 201 px window: its "light lost" is the window's, not the DOE's). The plain half is shown for
contrast (a sampled smooth wavefront, no envelope). float64, one thread.

Writes benchmarks/results/psf_defocus_staircase.{md,json}.
Run: .venv/bin/python benchmarks/psf_defocus_staircase.py
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import torch

import doefab
from doefab.pipeline.sampling import source_phase_step
from doefab.tasks.halfring import HalfRingTask

OUT = Path(__file__).resolve().parent / "results"
LAM, FOCUS = 486e-9, 3.5
KERNEL = 201  # px: holds the blur at the largest step asked (1.4 rad: 119 px across) and most of the random map's
#               scatter, inside the 512-pixel pupil's alias-free field (266 px)


def _camera():
    return doefab.Camera(doe_pixels=512, doe_pitch=8.64e-3 / 512, aperture_diameter=8.64e-3, focus_distance=FOCUS)


def _depth_for_step(cam, step: float) -> float:
    """The depth (nearer than the focus) whose wavefront changes by ``step`` rad between DOE pixels at the rim."""
    lo, hi = 0.05, FOCUS
    for _ in range(80):  # the step grows monotonically as the point comes nearer
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if source_phase_step(cam, LAM, mid) > step else (lo, mid)
    return math.sqrt(lo * hi)


def _heights(cam) -> dict:
    rng = np.random.default_rng(0)
    blocks = rng.integers(0, 16, (cam.doe_pixels // 4, cam.doe_pixels // 4))
    step = LAM / (float(cam.material.index(LAM)) - 1) / 16
    return {"half-ring start": HalfRingTask().init_height(cam, np.random.default_rng(0)),
            "random 16 levels": np.kron(blocks, np.ones((4, 4))) * step}


def _psf(cam, h, z: float, q: int, half: str, kernel: int) -> np.ndarray:
    pair = doefab.split_aperture_psf(h, cam, [LAM], [z], kernel_size=kernel, halves=(half,), precision="float64",
                                     pupil_oversample=q)
    return getattr(pair, half)[0, 0].numpy()


def measure(steps) -> list[dict]:
    cam = _camera()
    rows = []
    for name, h in _heights(cam).items():
        for step in steps:
            z = _depth_for_step(cam, step)
            kernel = KERNEL
            for half in ("coded", "uncoded"):
                if half == "uncoded" and name != "half-ring start":
                    continue  # the plain half carries no DOE
                p1, p2, p4 = (_psf(cam, h, z, q, half, kernel) for q in (1, 2, 4))
                ref = (4 * p4 - p2) / 3  # Richardson: the error falls as 1 / q²
                rows.append({"doe": name if half == "coded" else "(plain half)", "half": half,
                             "step_rad": source_phase_step(cam, LAM, z), "depth_m": z, "kernel_px": kernel,
                             "rel_l2_q1": float(np.linalg.norm(p1 - ref) / np.linalg.norm(ref)),
                             "rel_l2_q2": float(np.linalg.norm(p2 - ref) / np.linalg.norm(ref)),
                             "lost_q1": float(1 - p1.sum() / ref.sum()),
                             "estimate_rel_l2": step**2 / (12 * math.sqrt(3)) if half == "coded" else None,
                             "estimate_lost": step**2 / 24 if half == "coded" else None})
                print(rows[-1], flush=True)
    return rows


def write(rows) -> None:
    OUT.mkdir(exist_ok=True)
    (OUT / "psf_defocus_staircase.json").write_text(json.dumps({"rows": rows, "torch_threads": 1}, indent=1) + "\n")
    lines = [f"`.venv/bin/python benchmarks/psf_defocus_staircase.py`: 8.64 mm aperture on 512 DOE pixels "
             f"({8.64e3 / 512:.1f} µm), {LAM * 1e9:.0f} nm, focused at {FOCUS:g} m, float64, torch on 1 thread; the "
             f"reference is the Richardson limit of pupil_oversample q = 2 and 4.", "",
             "| coded DOE | phase step per DOE pixel (rad) | point at (m) | relative L2, q = 1 | estimate Δφ²/(12√3) "
             "| relative L2, q = 2 | light lost, q = 1 | estimate Δφ²/24 |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        est = (f"{r['estimate_rel_l2']:.2e}", f"{r['estimate_lost'] * 100:.2f} %") if r["estimate_rel_l2"] else ("",
                                                                                                               "")
        lines.append(f"| {r['doe']} | {r['step_rad']:.3f} | {r['depth_m']:.3f} | {r['rel_l2_q1']:.2e} | {est[0]} | "
                     f"{r['rel_l2_q2']:.2e} | {r['lost_q1'] * 100:.2f} % | {est[1]} |")
    (OUT / "psf_defocus_staircase.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=float, nargs="+", default=[0.1, 0.2, 0.45, 0.9, 1.4])
    args = ap.parse_args()
    torch.set_num_threads(1)
    write(measure(args.steps))


if __name__ == "__main__":
    main()
