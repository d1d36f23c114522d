"""The seed's Tables 1–3 on our held-out test split: every variant's shipped network, the same test scenes.

``evaluate(task, out_dir)`` writes ``metrics.json``
(``{"task", "test_images", "seed", "size_px", "rows": {"proposed": {...}, "coded_only": {...},
"uncoded_only": {...}}}``) and ``examples.png`` (inputs, each variant's output, ground truth, error map).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from doefab.io import atomic_write_json
from doefab.reconstruction.data import SPLIT_SEEDS
from doefab.reconstruction.loader import load_reconstructor
from doefab.reconstruction.metrics import mean_metrics, metrics_for
from doefab.reconstruction.networks import VARIANTS
from doefab.reconstruction.specs import make_batch, psf_pair

__all__ = ["evaluate"]


def evaluate(task: str, out_dir: str | Path, images: int = 16, size: int = 256, weights_dir=None,
             progress: bool = True, design=None, variants=VARIANTS) -> dict:
    from doefab.reconstruction.train import sensor_response_for

    out = Path(out_dir)
    recs = {v: load_reconstructor(task, v, weights_dir, design) for v in variants}  # refuse bad weights first
    pair, _ = psf_pair(task, design)
    response = sensor_response_for(task, pair)
    rows = {v: [] for v in variants}
    example = None
    it = range(images)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"evaluate {task}", unit="image")
    for i in it:
        coded, uncoded, target = make_batch(task, "test", [i], size, pair, response)
        preds = {}
        for v, rec in recs.items():
            p = rec(coded[0], uncoded[0])
            preds[v] = p.numpy() if isinstance(p, torch.Tensor) else p
            rows[v].append(metrics_for(task, preds[v], target[0].numpy()))
        if example is None:
            example = (coded[0].numpy(), uncoded[0].numpy(), target[0].numpy(), preds)
    summary = {v: mean_metrics(rs) for v, rs in rows.items()}
    result = {"task": task, "test_images": images, "seed": SPLIT_SEEDS["test"], "size_px": size,
              "noise": "default (Poisson–Gaussian)", "rows": summary,
              "weights": {v: {"steps": r.meta["training"]["steps"], "wall_time_s": r.meta["training"]["wall_time_s"],
                              "lr_schedule": r.meta["training"].get("schedule", "constant")}
                          for v, r in recs.items()}}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "metrics.json", result)
    _figure(out / "examples.png", task, *example)
    return result


def _show(task, arr):
    """An image for display: HDR tone-mapped (log), spectra as their band mean, depth as is."""
    if task == "hdr":
        return np.clip(np.log1p(np.moveaxis(arr, 0, -1)) / np.log1p(256.0), 0, 1)
    if task == "hyperspectral":
        return arr.mean(axis=0)
    return arr


def _figure(path: Path, task: str, coded, uncoded, target, preds) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("coded capture", np.moveaxis(coded, 0, -1) ** (1 / 2.2), None),
              ("uncoded capture", np.moveaxis(uncoded, 0, -1) ** (1 / 2.2), None)]
    unit = {"hdr": "log(1 + radiance) / log(257)", "hyperspectral": "band-mean radiance", "depth": "depth (m)"}[task]
    for v, p in preds.items():
        panels.append((f"{v.replace('_', '-')} output", _show(task, p), unit))
    panels.append(("ground truth", _show(task, target), unit))
    ref = "proposed" if "proposed" in preds else next(iter(preds))
    err = np.abs(preds[ref] - target)
    err = err.mean(axis=0) if err.ndim == 3 else err
    panels.append((f"|{ref.replace('_', '-')} − truth|", err, {"hdr": "radiance", "hyperspectral": "radiance", "depth": "m"}[task]))
    fig, axes = plt.subplots(2, 4, figsize=(13, 6.6), layout="constrained")
    for ax, (title, img, cb) in zip(axes.flat, panels):
        kw = {"cmap": "viridis"} if img.ndim == 2 else {}
        if task == "depth" and cb == "depth (m)":
            kw.update(vmin=1.0, vmax=5.0)
        im = ax.imshow(np.clip(img, 0, None) if img.ndim == 3 else img, **kw)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x (pixels)", fontsize=7)
        ax.set_ylabel("y (pixels)", fontsize=7)
        ax.tick_params(labelsize=6)
        if img.ndim == 2:
            c = fig.colorbar(im, ax=ax, shrink=0.8)
            c.set_label(cb, fontsize=7)
            c.ax.tick_params(labelsize=6)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    fig.suptitle(f"{task}: held-out test scene", fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)
