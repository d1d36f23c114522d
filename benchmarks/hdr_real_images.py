"""The shipped HDR networks on real photographs they never saw: scikit-image's colour photographs of the test split
(``doefab.reconstruction.data.IMAGES["test"]``; split used: test), made HDR by
brightening their brightest 3 % of pixels 60× (so 4–6 % of the plain capture clips, as in the test set), sent
through the committed streak design's captures (default noise, seed 1) and reconstructed by each variant.

    .venv/bin/python benchmarks/hdr_real_images.py [--size 256] [--weights-dir DIR] [--out FILE]

Writes benchmarks/results/hdr_real_images.json: per image and variant, Table 1's metrics (peak 2^8).
The highlights here are the photographs' own bright regions, not the generator's lamps, discs and windows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.reconstruction.data import IMAGES as SPLIT_IMAGES  # noqa: E402

IMAGES = SPLIT_IMAGES["test"]  # the test split's photographs only: none was seen in training or validation
VARIANTS = ("proposed", "coded_only", "uncoded_only")


def hdr_scene(name: str, size: int) -> np.ndarray:
    """[3, size, size] linear radiance: the photograph at 0.9 of full well, its brightest 3 % of pixels 60×."""
    from skimage import data, transform

    img = getattr(data, name)().astype(np.float32) / 255.0
    img = transform.resize(img, (size, size), anti_aliasing=True).astype(np.float32).transpose(2, 0, 1)
    lum = img.mean(axis=0)
    scene = 0.9 * img
    scene[:, lum > np.quantile(lum, 0.97)] *= 60.0
    return np.clip(scene, 0.0, 256.0).astype(np.float32)


def main() -> None:
    import torch

    import doefab
    from doefab.io import atomic_write_json
    from doefab.reconstruction.metrics import hdr_metrics

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256, help="image side (px, a multiple of 32)")
    ap.add_argument("--weights-dir", default=None, help="weights folder (default: the shipped ones)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "hdr_real_images.json"))
    args = ap.parse_args()
    torch.set_num_threads(2)
    kw = {"weights_dir": args.weights_dir} if args.weights_dir else {}
    recs = {v: doefab.load_reconstructor("hdr", variant=v, **kw) for v in VARIANTS}
    pair = recs["proposed"].pair
    rows = {}
    for name in IMAGES:
        scene = hdr_scene(name, args.size)
        coded, uncoded = doefab.simulate_captures(scene, pair, seed=1)
        rows[name] = {"clipped_percent": float((uncoded >= 0.98).any(axis=0).mean() * 100),
                      **{v: hdr_metrics(np.asarray(r(coded, uncoded)), scene) for v, r in recs.items()}}
        print(name, " | ".join(f"{v}: RMSE {rows[name][v]['rmse']:.2f}, highlight PSNR "
                               f"{rows[name][v]['psnr_highlight']:.2f} dB" for v in VARIANTS), flush=True)
    out = Path(args.out)
    atomic_write_json(out, {"size_px": args.size, "weights_dir": args.weights_dir or "shipped",
                            "design_levels_sha256": recs["proposed"].design_sha256, "psnr_peak": 256, "rows": rows})
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
