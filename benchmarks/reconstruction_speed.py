"""Speed of the reconstruction stage on this machine: capture simulation of a 512 × 512 scene per task,
reconstruction of a 512 × 512 capture pair per task with the shipped proposed network (target ≤ 2 s each),
and training steps per second (from the shipped weights' records). Medians of 3 runs. Split used: one
validation scene per task (only its size matters: no choice is made on it).
Writes benchmarks/results/reconstruction_speed.md. Run: .venv/bin/python benchmarks/reconstruction_speed.py
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path


OUT = Path(__file__).parent / "results"


def median_time(fn, repeats=3):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main():
    import torch

    import doefab
    from doefab.reconstruction.data import depth_sample, hdr_sample, sample_rng, spectral_sample
    from doefab.reconstruction.specs import psf_pair

    torch.set_num_threads(2)
    rows = ["| task | capture simulation, 512² (s) | reconstruction, 512² (s) | training steps / s (batch 4) | "
            "training crop (px) |", "| --- | --- | --- | --- | --- |"]
    for task in ("hdr", "hyperspectral", "depth"):
        pair, _ = psf_pair(task)
        rng = sample_rng("val", 0)
        depth = None
        response = None
        if task == "hdr":
            scene = hdr_sample(rng, 512, "val")
        elif task == "hyperspectral":
            scene = spectral_sample(rng, 512, "val")
            response = doefab.sensor_response(pair.wavelengths)
        else:
            scene, depth = depth_sample(rng, 512, "val")
        sim = median_time(lambda: doefab.simulate_captures(scene, pair, depth_map=depth, response=response))
        coded, uncoded = doefab.simulate_captures(scene, pair, depth_map=depth, response=response)
        rec = doefab.load_reconstructor(task)
        recon = median_time(lambda: rec(coded, uncoded))
        tr = rec.meta["training"]
        rows.append(f"| {task} | {sim:.2f} | {recon:.2f} | {tr['steps'] / tr['wall_time_s']:.2f} | {tr['crop_px']} |")
        print(rows[-1], flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "reconstruction_speed.md").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
