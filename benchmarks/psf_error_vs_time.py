"""Error against run time of the PSF routes (hyperspectral case).

Case: the hyperspectral preset (1600² DOE grid at 5.4 µm), a 16-level blazed grating of period 16 DOE pixels,
point in focus, 31 bands 400–700 nm, coded half, K = 512 sensor pixels with pixel integration.
Reference: float64, spectral route with 3× finer pupil sampling (exact pixel integrals); its own accuracy is
shown by the q = 2 → 3 change and by an independent cross-check (matrix Fourier transform, 8 Gauss–Legendre
nodes per pixel and axis) at q = 1.

Writes benchmarks/results/psf_error_vs_time.{csv,md,png}. Run: .venv/bin/python benchmarks/psf_error_vs_time.py
"""

from __future__ import annotations

import argparse
import csv
import statistics
import time
from pathlib import Path

import numpy as np

import doefab
from doefab.errors import SamplingError
from doefab.optics.propagators.baseline import authors_fresnel_psf

OUT = Path(__file__).parent / "results"


def timed(fn, repeats):
    times, result = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t)
        if times[-1] > 30:
            break
    return statistics.median(times), result


def errors(psf, ref):
    psf = np.asarray(psf, np.float64)
    return float(np.linalg.norm(psf - ref) / np.linalg.norm(ref)), float(np.abs(psf - ref).max() / ref.max())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bands", type=int, default=31, help="number of bands in 400–700 nm (default 31)")
    ap.add_argument("--kernel", type=int, default=512, help="K, sensor pixels (default 512)")
    ap.add_argument("--repeats", type=int, default=3, help="timing repeats, median reported (default 3)")
    ap.add_argument("--ref-oversample", type=int, default=3, help="reference pupil oversampling (default 3)")
    args = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    cam = doefab.Camera.preset("hyperspectral")
    lams = np.linspace(400e-9, 700e-9, args.bands)
    depth = cam.focus_distance
    h = doefab.blazed_grating_height(cam, 16, n_levels=16)
    k = args.kernel

    def ours(route, precision="float32", q=1, **opt):
        def run():
            plan = doefab.PSFPlan(cam, lams, [depth], k, halves=("coded",), route=route, precision=precision,
                                  pupil_oversample=q, **opt)
            return plan(h).coded[0].numpy()
        return run

    print(f"reference: spectral, float64, pupil oversample {args.ref_oversample} …", flush=True)
    t_ref, ref = timed(ours("spectral", "float64", args.ref_oversample), 1)
    ref = ref.astype(np.float64)
    rows = []
    settings = [
        ("spectral (default)", "q=1 float32", ours("spectral")),
        ("spectral", "q=1 float64", ours("spectral", "float64")),
        ("spectral", "q=2 float32", ours("spectral", "float32", 2)),
        ("spectral", "q=2 float64", ours("spectral", "float64", 2)),
        ("mft", "1 node/pixel", ours("mft", pixel_nodes=1)),
        ("mft", "2 nodes/pixel", ours("mft", pixel_nodes=2)),
        ("mft", "4 nodes/pixel", ours("mft", pixel_nodes=4)),
        ("mft", "6 nodes/pixel", ours("mft", pixel_nodes=6)),
        ("mft", "8 nodes/pixel float64 (cross-check)", ours("mft", "float64", pixel_nodes=8)),
        ("fft", "2 samples/pixel", ours("fft", oversample=2)),
        ("fft", "4 samples/pixel", ours("fft", oversample=4)),
        ("fft", "8 samples/pixel", ours("fft", oversample=8)),
        ("authors (Fresnel TF, R/2 pad, pooling)", "baseline",
         lambda: authors_fresnel_psf(h, cam, lams, depth, k)),
        ("asm", "lens sphere + band-limited ASM", ours("asm")),
    ]
    for name, setting, fn in settings:
        print(f"{name:40s} {setting:38s}", end=" ", flush=True)
        try:
            t, psf = timed(fn, args.repeats)
        except SamplingError as exc:
            print("refused:", str(exc)[:100])
            rows.append(dict(route=name, setting=setting, time_s="", rel_l2="", rel_max="", note=f"refused: {exc}"))
            continue
        l2, mx = errors(psf, ref)
        print(f"{t:8.2f} s  rel L2 {l2:.2e}  max {mx:.2e}")
        rows.append(dict(route=name, setting=setting, time_s=f"{t:.2f}", rel_l2=f"{l2:.2e}", rel_max=f"{mx:.2e}",
                         note=""))
    # reference convergence: q=2 vs q=3 (float64)
    with open(OUT / "psf_error_vs_time.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [f"Hyperspectral case: {args.bands} bands 400–700 nm, 1600² pupil at 5.4 µm, 16-level blazed grating "
             f"(Λ = 16 px), point in focus, coded half, K = {k}; reference float64 spectral route with pupil "
             f"oversampling {args.ref_oversample} ({t_ref:.0f} s). Times are medians of {args.repeats} runs "
             f"(plan + forward, 2 cores).", "",
             "| route | setting | time (s) | rel. L2 error | rel. max error |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        if r["note"]:
            lines.append(f"| {r['route']} | {r['setting']} | refused | — | {r['note'].split(':')[1][:90]}… |")
        else:
            lines.append(f"| {r['route']} | {r['setting']} | {r['time_s']} | {r['rel_l2']} | {r['rel_max']} |")
    (OUT / "psf_error_vs_time.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in rows:
        if r["note"]:
            continue
        ax.loglog(float(r["time_s"]), float(r["rel_l2"]), "o")
        ax.annotate(f"{r['route'].split(' (')[0]} {r['setting']}", (float(r["time_s"]), float(r["rel_l2"])),
                    fontsize=7, xytext=(4, 2), textcoords="offset points")
    ax.axhline(1e-3, color="grey", ls="--", lw=0.8)
    ax.axvline(5, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("wall time, plan + forward (s, median)")
    ax.set_ylabel("relative L2 error vs reference")
    ax.set_title(f"Coded PSF, {args.bands} bands, K = {k}")
    fig.tight_layout()
    fig.savefig(OUT / "psf_error_vs_time.png", dpi=130)


if __name__ == "__main__":
    main()
