"""The proposed hyperspectral network's starting estimate, with no network, on VALIDATION scenes (a choice of the
estimate is made here; the test split is for the final tables): the spectra from the uncoded capture under

- the single library illuminant whose predicted coded capture fits best (``search_illuminant``),
- a non-negative mixture of the library's estimates fitted to the coded capture (``mix_illuminants``),
- a flat illuminant (the uncoded-only baseline),

for light in the library and light outside it, captured under the honest conditions (fabricated parts of the
validation split, calibrated crosstalk, noise) through the committed grating design.

    .venv/bin/python benchmarks/illuminant_search.py [--images 16] [--size 128]

Writes benchmarks/results/illuminant_search.json and .md: mean PSNR (dB), SSIM and SAM (rad) per estimate and
light kind, and the median seconds of each estimate per image.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_json, atomic_write_text  # noqa: E402
from doefab.reconstruction.illuminant import mix_illuminants, search_illuminant  # noqa: E402
from doefab.reconstruction.metrics import mean_metrics, spectral_metrics  # noqa: E402
from doefab.reconstruction.models import build_model, default_arch  # noqa: E402
from doefab.reconstruction.spectra import light_kind  # noqa: E402
from doefab.reconstruction.specs import make_batch, psf_pair  # noqa: E402
from doefab.reconstruction.train import sensor_response_for  # noqa: E402
from doefab.tolerance.conditions import for_splits  # noqa: E402

SPLIT = "val"
OUT = Path(__file__).resolve().parent / "results"


def estimates(coded, uncoded, psf, net) -> dict:
    """{name: ([C, H, W] estimate, seconds)} of one capture pair."""
    out = {}
    t = time.perf_counter()
    idx, _ = search_illuminant(coded, uncoded, psf, net.response, net.inverses)
    out["best single illuminant"] = (torch.einsum("oc,chw->ohw", net.inverses[idx[0]], uncoded[0]),
                                     time.perf_counter() - t)
    t = time.perf_counter()
    w = mix_illuminants(coded, uncoded, psf, net.response, net.inverses)
    inv = torch.einsum("j,joc->oc", w[0] / max(float(w[0].sum()), 1e-12), net.inverses)
    out["mixture of illuminants"] = (torch.einsum("oc,chw->ohw", inv, uncoded[0]), time.perf_counter() - t)
    t = time.perf_counter()
    out["flat illuminant (uncoded only)"] = (torch.einsum("oc,chw->ohw", net.baseline, uncoded[0]),
                                             time.perf_counter() - t)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=16)
    ap.add_argument("--size", type=int, default=128, help="image side (px)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    pair, sha = psf_pair("hyperspectral")
    response = sensor_response_for("hyperspectral", pair)
    cond = for_splits("hyperspectral", None, "honest", (SPLIT,), progress=True)[SPLIT]
    net = build_model("hyperspectral", "proposed", default_arch("hyperspectral", "proposed")).eval()
    psf = pair.coded[0].float()
    rows: dict = {}
    secs: dict = {}
    for i in range(args.images):
        coded, uncoded, target = make_batch("hyperspectral", SPLIT, [i], args.size, pair, response, conditions=cond,
                                            images=args.images)
        kind = light_kind(SPLIT, i)
        for name, (est, s) in estimates(coded, uncoded, psf, net).items():
            m = spectral_metrics(est.clamp_min(0).numpy(), target[0].numpy())
            rows.setdefault(name, {}).setdefault(kind, []).append(m)
            secs.setdefault(name, []).append(s)
        print(f"scene {i} ({kind}) done", flush=True)
    result = {"split": SPLIT, "images": args.images, "size_px": args.size, "design_levels_sha256": sha,
              "conditions": cond.describe(),
              "rows": {n: {k: mean_metrics(v) for k, v in by.items()} for n, by in rows.items()},
              "seconds_per_image": {n: float(np.median(v)) for n, v in secs.items()}}
    atomic_write_json(OUT / "illuminant_search.json", result)
    lines = [f"Starting estimates of the proposed hyperspectral network, no network ({args.images} validation scenes "
             f"of {args.size}² px, honest captures; `.venv/bin/python benchmarks/illuminant_search.py`).", "",
             "| estimate | light | PSNR (dB) | SSIM | SAM (rad) | s per image |", "| --- | --- | --- | --- | --- | --- |"]
    for n, by in result["rows"].items():
        for k, m in by.items():
            lines.append(f"| {n} | {k} | {m['psnr']:.2f} | {m['ssim']:.3f} | {m['sam']:.3f} | "
                         f"{result['seconds_per_image'][n]:.3f} |")
    atomic_write_text(OUT / "illuminant_search.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
