"""How much of the clipped highlights the captures give back with no network: the least-squares solve
(``doefab/reconstruction/highlights.py``) from both captures, the coded one, the uncoded one, against its
iteration count, and with the bounded stage the shipped networks use, on VALIDATION scenes of the shipped
generator through the committed streak design, captured under the honest conditions the tables use (fabricated
parts, calibrated crosstalk; split used: val; the solver's settings are chosen here, the test split is for the
final tables).

    .venv/bin/python benchmarks/hdr_solve.py [--images 12] [--size 256] [--iters 0 20 40] [--bound 40 8]

Writes benchmarks/results/hdr_solve.json: per view set and configuration, the mean over images of Table 1's
metrics (RMSE and PSNR with peak 2^8, overall and in highlights) and the median seconds per image.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_json  # noqa: E402
from doefab.reconstruction.highlights import solve_highlights  # noqa: E402
from doefab.reconstruction.metrics import hdr_metrics  # noqa: E402
from doefab.reconstruction.specs import make_batch, psf_pair  # noqa: E402
from doefab.tolerance.conditions import for_splits  # noqa: E402

KEYS = ("rmse", "psnr", "rmse_highlight", "psnr_highlight")
SPLIT = "val"
VIEW_SETS = {"both": ("coded", "uncoded"), "coded": ("coded",), "uncoded": ("uncoded",)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--size", type=int, default=256, help="image side (px)")
    ap.add_argument("--iters", type=int, nargs="+", default=[0, 20, 40], help="least-squares iterations")
    ap.add_argument("--bound", type=int, nargs=2, default=[40, 8], metavar=("ITERS", "ROUNDS"),
                    help="the bounded stage after the last --iters: iterations and restarts")
    args = ap.parse_args()
    torch.set_num_threads(2)
    pair, sha = psf_pair("hdr")
    pc, pu = pair.coded[0].float(), pair.uncoded[0].float()
    cond = for_splits("hdr", None, "honest", (SPLIT,))[SPLIT]  # the conditions the tables are measured under
    coded, uncoded, target = make_batch("hdr", SPLIT, range(args.images), args.size, pair, conditions=cond)
    rows = []
    for name, views in VIEW_SETS.items():
        configs = [(iters, 0, 1) for iters in args.iters] + [(args.iters[-1], *args.bound)]
        for iters, bound_iters, rounds in configs:
            metrics, secs = [], []
            for i in range(args.images):
                t0 = time.perf_counter()
                x = solve_highlights(coded[i:i + 1], uncoded[i:i + 1], pc, pu, iters, views,
                                     bound_iters=bound_iters, bound_rounds=rounds)
                secs.append(time.perf_counter() - t0)
                metrics.append(hdr_metrics(x[0].numpy(), target[i].numpy()))
            row = {"views": name, "iters": iters, "bound_iters": bound_iters, "bound_rounds": rounds,
                   "seconds_per_image": float(np.median(secs)),
                   **{k: float(np.nanmean([m[k] for m in metrics])) for k in KEYS}}
            rows.append(row)
            print(f"{name:8s} {iters:3d} + {bound_iters:3d} bounded iterations: RMSE {row['rmse']:.3f}, "
                  f"PSNR {row['psnr']:.2f} dB, highlight RMSE {row['rmse_highlight']:.2f}, highlight PSNR "
                  f"{row['psnr_highlight']:.2f} dB, {row['seconds_per_image']:.3f} s/image", flush=True)
    out = Path(__file__).parent / "results" / "hdr_solve.json"
    atomic_write_json(out, {"images": args.images, "size_px": args.size, "split": SPLIT,
                            "design_levels_sha256": sha, "psnr_peak": 256, "rows": rows})
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
