"""Fabricated-PSF error against the simulation grid's supersampling, and its run time (issue: tolerance).

A sub-pixel error (every mask overlaid by a different 0.3–0.8 µm shift, 0.1 µm edge bias) on a central
320 × 320-pixel block of the committed grating design (5.4 µm pixels, 31 bands, K = 191), so the finest grids
stay within memory. Reference: supersample 8. Error: relative L2 of the coded PSF stack, and the change of the
task metric. Medians of 3 timings. Writes benchmarks/results/tolerance_supersample.md.
Run: .venv/bin/python benchmarks/tolerance_supersample.py
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).parent / "results"


def main():
    import torch

    import doefab
    from doefab.design.design import Design
    from doefab.tasks import get_task
    from doefab.tolerance.fabricate import fabricated_height, refined_camera

    torch.set_num_threads(2)
    d = Design.load("masks/grating/design")
    n = 320
    c0 = d.camera.doe_pixels // 2
    lv = d.levels[c0 - n // 2:c0 + n // 2, c0 - n:c0]  # coded-half block (left of the split)
    lv = np.concatenate([lv, np.full((n, n // 2), 15, np.uint8)], axis=1)[:, n // 4:n // 4 + n]
    cam = d.camera.replace(doe_pixels=n, aperture_diameter=n * d.camera.doe_pitch * 0.98)
    task = get_task("grating", **d.task_params)
    task.bind(d.camera)
    kw = dict(overlay=((0.3e-6, 0.0), (0.0, 0.5e-6), (-0.8e-6, 0.4e-6), (0.6e-6, -0.3e-6)), edge_bias=0.1e-6)
    res = {}
    for s in (1, 2, 4, 8):
        fine = refined_camera(cam, s)
        plan = doefab.PSFPlan(fine, d.wavelengths, d.depths, task.kernel_size, halves=("coded",))
        times = []
        for _ in range(3 if s < 8 else 1):
            t = time.perf_counter()
            h = fabricated_height(lv, cam, cam.design_wavelength, supersample=s, **kw)
            with torch.no_grad():
                psf = plan(h).coded.double()
            times.append(time.perf_counter() - t)
        res[s] = (psf, statistics.median(times), task.metric(psf.float(), fine)["value"])
        print(s, res[s][1], res[s][2], flush=True)
    ref = res[8][0]
    rows = ["| supersample | grid | time (s) | rel. L2 error of the PSF | task metric | metric error |",
            "| --- | --- | --- | --- | --- | --- |"]
    for s, (psf, t, m) in res.items():
        err = float((psf - ref).norm() / ref.norm())
        rows.append(f"| {s} | {n * s}² | {t:.2f} | {err:.2e} | {m:.4f} | {m - res[8][2]:+.4f} |")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "tolerance_supersample.md").write_text("\n".join(rows) + "\n")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
