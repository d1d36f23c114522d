"""What the shipped proposed depth network reads for a fronto-parallel plane: each of several planes across the
design range (1–5 m) and beyond it, behind each of a few photographs, captured through the committed half-ring
with the default sensor noise (seed 0). The depth a user sees for a wall at a known distance, plane by plane.

Photographs: scikit-image's sample images (astronaut, coffee, chelsea, rocket; public domain or CC0), resized to
the frame with a margin of half the PSF window that is simulated and cropped away, scaled to 0.05–0.9. Planes
inside the range are rendered by ``simulate_captures`` at a constant depth map (between the network's planes
where they fall between); planes outside take the design's own PSFs at that plane. The value per plane and photo is
the median over the frame's interior (32 px in from each edge). Writes benchmarks/results/depth_planes.{md,json}:
    .venv/bin/python benchmarks/depth_planes.py
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "benchmarks" / "results"
INSIDE = (1.0, 1.25, 1.5, 2.0, 3.0, 4.0, 5.0)
OUTSIDE = (0.7, 8.0, 20.0, math.inf)
PHOTOS = ("astronaut", "coffee", "chelsea", "rocket")
SIZE, EDGE = 256, 32


def _photo(name: str, side: int):
    import numpy as np
    from skimage import data, transform

    im = transform.resize(getattr(data, name)(), (side, side), anti_aliasing=True)
    return (0.05 + 0.85 * im).astype(np.float32).transpose(2, 0, 1)


def _read(rec, scene, pair, margin: int, depth_map=None) -> float:
    import numpy as np

    import doefab

    c, u = doefab.simulate_captures(scene, pair, depth_map=depth_map, noise="default", seed=0)
    crop = (slice(None), slice(margin, -margin), slice(margin, -margin))
    out = rec(np.asarray(c)[crop].copy(), np.asarray(u)[crop].copy())
    return float(np.median(out[EDGE:-EDGE, EDGE:-EDGE]))


def measure() -> dict:
    import numpy as np
    import torch

    import doefab
    from doefab.design.design import Design
    from doefab.optics.psf import PSFPlan
    from doefab.reconstruction.specs import design_dir, network_kernel

    torch.set_num_threads(2)
    rec = doefab.load_reconstructor("depth")
    margin = rec.pair.coded.shape[-1] // 2
    side = SIZE + 2 * margin
    design = Design.load(design_dir("depth"))
    reads: dict = {}
    for name in PHOTOS:
        scene = _photo(name, side)
        for z in INSIDE:
            reads.setdefault(z, {})[name] = _read(rec, scene, rec.pair, margin, np.full((side, side), z, np.float32))
        for z in OUTSIDE:
            plan = PSFPlan(design.camera, design.wavelengths, [z],
                           network_kernel("depth", design.task_params.get("kernel_size")))
            with torch.no_grad():
                pair = plan(design.quantized_height)
            reads.setdefault(z, {})[name] = _read(rec, scene, pair, margin)
        print(name, {z: round(v[name], 2) for z, v in reads.items()}, flush=True)
    return {"size_px": SIZE, "edge_px": EDGE, "photos": list(PHOTOS), "threads": 2,
            "reads_m": {("inf" if math.isinf(z) else f"{z:g}"): v for z, v in reads.items()}}


def markdown(res: dict) -> str:
    rows = ["| plane (m) | inside 1–5 m | median read (m) | lowest – highest photo (m) |", "| --- | --- | --- | --- |"]
    for z, v in res["reads_m"].items():
        vals = sorted(v.values())
        mid = (vals[len(vals) // 2 - 1] + vals[len(vals) // 2]) / 2 if len(vals) % 2 == 0 else vals[len(vals) // 2]
        inside = "yes" if z != "inf" and 1.0 <= float(z) <= 5.0 else "no"
        rows.append(f"| {z} | {inside} | {mid:.2f} | {vals[0]:.2f} – {vals[-1]:.2f} |")
    return ("The shipped proposed depth network's read of a fronto-parallel plane behind "
            f"{len(res['photos'])} photographs ({', '.join(res['photos'])}), {res['size_px']}² px, default sensor "
            f"noise, median over the frame {res['edge_px']} px in from each edge; torch on {res['threads']} threads "
            "(`.venv/bin/python benchmarks/depth_planes.py`).\n\n" + "\n".join(rows) + "\n")


def main() -> int:
    from doefab.io import atomic_write_json, atomic_write_text

    res = measure()
    atomic_write_json(RESULTS / "depth_planes.json", res)
    atomic_write_text(RESULTS / "depth_planes.md", markdown(res))
    print(markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
