"""How well ``doefab reconstruct`` tells capture pairs given the wrong way round (``capturenotes.swapped_note``).

For each task, scenes of the validation split (``val``, doefab's generators) and of the measured-data split (``real``:
data doefab did not make), rendered through both halves of the shipped network's PSF pair (at each pixel's plane
for depth) and seen by the default sensor response; each view exposed so that the plain view's 99th percentile sits
at 0.8 of full scale, with 0.5 % of full scale of Gaussian read noise, clipped to [0, 1]. Each pair is checked as
given and swapped: the check's two mismatches (1 − r² of coded ⊛ PSF_plain against plain ⊛ PSF_coded) and whether
it warns; nothing to tell by: no pixel whose PSF window holds no clipped pixel, or no
structure (no warning). The test split is not read.

    .venv/bin/python benchmarks/swapped_views.py [--scenes 8] [--size 384]

Writes benchmarks/results/swapped_views.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

OUT = Path(__file__).resolve().parent / "results" / "swapped_views.md"
TASKS = ("hdr", "hyperspectral", "depth")
SPLITS = ("val", "real")


def views(task: str, split: str, index: int, size: int, rec, response):
    """(coded, plain) [3, size, size] captures in [0, 1] of scene ``index`` of ``split``."""
    from doefab.reconstruction.specs import render_scene

    rng = np.random.default_rng(1000 + index)
    _, _, (c, u) = render_scene(task, split, index, rng, size, rec.pair, response)
    c, u = np.asarray(c, np.float64), np.asarray(u, np.float64)
    gain = 0.8 / max(float(np.percentile(u, 99)), 1e-9)
    return tuple(np.clip(v * gain + rng.normal(0, 0.005, v.shape), 0, 1) for v in (c, u))


def main(argv=None) -> None:
    import torch

    import doefab
    from doefab.lab.capturenotes import SWAPPED_GAP, SWAPPED_RATIO, channel_psfs, looks_swapped, view_mismatch
    from doefab.reconstruction.train import sensor_response_for

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", type=int, default=8, help="scenes per task and split")
    ap.add_argument("--size", type=int, default=384, help="scene side (px; the measured HDR maps hold 400 at most)")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    rows = ["| task | split | scenes | nothing to tell by | mismatch as given (median) | swapped (median) | warned as "
            "given | warned swapped |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for task in TASKS:
        rec = doefab.load_reconstructor(task)
        resp = sensor_response_for(task, rec.pair)
        resp = None if resp is None else torch.as_tensor(np.asarray(resp), dtype=torch.float32)
        pc, pu = channel_psfs(rec.pair)
        for split in SPLITS:
            got = []
            for i in range(a.scenes):
                c, u = views(task, split, i, a.size, rec, resp)
                got.append(view_mismatch(c, u, pc, pu))
                print(task, split, i, got[-1], flush=True)
            s, w = np.array(got).T
            rows.append(f"| {task} | {split} | {a.scenes} | {int(np.isnan(s).sum())} | {np.nanmedian(s):.3f} | "
                        f"{np.nanmedian(w):.3f} | "
                        f"{sum(looks_swapped(*g) for g in got)} | "
                        f"{sum(looks_swapped(*g[::-1]) for g in got)} |")
    text = [f"`.venv/bin/python benchmarks/swapped_views.py --scenes {a.scenes} --size {a.size}`: each pair checked as "
            f"given and swapped (warned where one order fits at most {SWAPPED_RATIO} as far off as the other and "
            f"closer by more than {SWAPPED_GAP}; "
            "mismatch: 1 − r² of coded ⊛ PSF_plain against plain ⊛ PSF_coded, the least over the pair's planes).", "",
            *rows]
    OUT.write_text("\n".join(text) + "\n")
    print("\n".join(text))


if __name__ == "__main__":
    main()
