"""How much light the shipped proposed HDR network puts into a clipped highlight of known radiance: a flat disc
of radius 2, 4 or 8 px at 10, 40 or 150 times the clip level, in the centre of a photograph, captured through the
committed streak with the default sensor noise (seed 1). The mean over the disc's pixels against its radiance, for
the network's output and for the bounded least-squares solve it refines (its ``_solve``, the same settings): the
bias of the highlight's brightness, which the PSNR tables do not show by sign.

Photographs: scikit-image's sample images (astronaut, coffee; public domain or CC0), 0.05–0.9, a 192² px frame
with a 48 px margin simulated and cropped away. Writes benchmarks/results/hdr_highlight_bias.{md,json}:
    .venv/bin/python benchmarks/hdr_highlight_bias.py
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "benchmarks" / "results"
RADII_PX, RADIANCES, PHOTOS = (2, 4, 8), (10.0, 40.0, 150.0), ("astronaut", "coffee")
SIZE, MARGIN = 192, 48


def _disc_means(rec, scene, disc) -> tuple[float, float]:
    """(network, solve) mean radiance over the disc's pixels (all colours)."""
    import numpy as np
    import torch

    import doefab

    c, u = doefab.simulate_captures(scene, rec.pair, noise="default", seed=1)
    crop = (slice(None), slice(MARGIN, -MARGIN), slice(MARGIN, -MARGIN))
    c, u = np.asarray(c)[crop].copy(), np.asarray(u)[crop].copy()
    inner = disc[MARGIN:-MARGIN, MARGIN:-MARGIN]
    net = rec(c, u)
    p = rec._psf(None)
    with torch.no_grad():
        solve = torch.expm1(rec.model._solve(torch.from_numpy(c)[None], torch.from_numpy(u)[None], p[0, :3],
                                             p[0, 3:]))[0].numpy()
    return float(net[:, inner].mean()), float(solve[:, inner].mean())


def measure() -> dict:
    import numpy as np
    import torch
    from skimage import data, transform

    import doefab

    torch.set_num_threads(2)
    rec = doefab.load_reconstructor("hdr")
    side = SIZE + 2 * MARGIN
    yy, xx = np.mgrid[:side, :side]
    rows = []
    for name in PHOTOS:
        base = (0.05 + 0.85 * transform.resize(getattr(data, name)(), (side, side), anti_aliasing=True))
        base = base.astype(np.float32).transpose(2, 0, 1)
        for r in RADII_PX:
            disc = (yy - side // 2) ** 2 + (xx - side // 2) ** 2 <= r ** 2
            for rad in RADIANCES:
                scene = base.copy()
                scene[:, disc] = rad
                net, solve = _disc_means(rec, scene, disc)
                rows.append({"photo": name, "radius_px": r, "radiance": rad, "network_bias": net / rad - 1,
                             "solve_bias": solve / rad - 1})
                print(rows[-1], flush=True)
    return {"size_px": SIZE, "threads": 2, "rows": rows}


def markdown(res: dict) -> str:
    lines = ["| disc radius (px) | radiance (× clip) | network's bias | least-squares solve's bias |",
             "| --- | --- | --- | --- |"]
    for r in RADII_PX:
        for rad in RADIANCES:
            got = [x for x in res["rows"] if x["radius_px"] == r and x["radiance"] == rad]
            net = " / ".join(f"{x['network_bias']:+.0%}" for x in got)
            solve = " / ".join(f"{x['solve_bias']:+.0%}" for x in got)
            lines.append(f"| {r} | {rad:g} | {net} | {solve} |")
    return (f"The mean radiance the shipped proposed HDR network and its least-squares solve give a flat clipped disc, "
            f"against the disc's radiance, in a {res['size_px']}² px frame of each photograph ("
            f"{' / '.join(PHOTOS)}), default sensor noise; torch on {res['threads']} threads "
            f"(`.venv/bin/python benchmarks/hdr_highlight_bias.py`).\n\n" + "\n".join(lines) + "\n")


def main() -> int:
    from doefab.io import atomic_write_json, atomic_write_text

    res = measure()
    atomic_write_json(RESULTS / "hdr_highlight_bias.json", res)
    atomic_write_text(RESULTS / "hdr_highlight_bias.md", markdown(res))
    print(markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
