"""The paper's Tables 1–3: every variant's network on the same held-out scenes, under the conditions a real camera
makes (``conditions``: ``doefab.tolerance.conditions.honest`` — a fabricated part's PSF, per-column crosstalk
unmixed with a noisy calibration, depth between the network's planes — while the network is told the nominal
PSF; ``doefab evaluate``'s default) or the nominal model's own captures (None). The test split is for the final tables; ``split="val"`` is for
every choice made along the way.

``evaluate(task, out_dir)`` writes ``metrics.json`` (``{"task", "split", "conditions", "images", "size_px",
"rows": {variant: means}, "by_light": {"in-library" | "out-of-library": {variant: means}}, "per_image":
{"light", "rows": {variant: [metrics of each scene]}}}``; the light groups for hyperspectral) and
``examples.png`` (inputs, each variant's output, ground truth, error map).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.io import atomic_write_json
from doefab.reconstruction.data import SPLIT_SEEDS, split_digest
from doefab.reconstruction.loader import load_reconstructor
from doefab.reconstruction.metrics import mean_metrics, metrics_for
from doefab.reconstruction.networks import VARIANTS
from doefab.reconstruction.specs import make_batch, psf_pair

__all__ = ["evaluate"]


def evaluate(task: str, out_dir: str | Path, images: int = 16, size: int = 256, weights_dir=None,
             progress: bool = True, design=None, variants=VARIANTS, conditions=None, split: str = "test",
             other_design: bool = False, sensor=None) -> dict:
    """``conditions``: the split's capture conditions (``doefab.tolerance.conditions``; None: clean).
    ``sensor``: the camera's ``imaging.sensor.Sensor`` that makes the captures (response, noise; None: the
    default camera's). ``other_design``: evaluate networks trained for another design or sensor on these
    captures (they are told ``design``'s PSFs); the result says so."""
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.spectra import light_kind
    from doefab.reconstruction.train import sensor_response_for

    if split not in ("val", "test"):
        raise DoefabError(f"split must be val or test, got {split!r}")
    out = Path(out_dir)
    sensor = sensor or Sensor()
    recs = {v: load_reconstructor(task, v, weights_dir, design, other_design, sensor)
            for v in variants}  # refuse first
    pair, _ = psf_pair(task, design)
    response = sensor_response_for(task, pair, sensor)
    cond = conditions
    rows = {v: [] for v in variants}
    kinds = []
    example = None
    it = range(images)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"evaluate {task} ({cond.name if cond else 'clean'}, {split})", unit="image")
    for i in it:
        coded, uncoded, target = make_batch(task, split, [i], size, pair, response, sensor.noise(), conditions=cond,
                                            images=images)  # scene i's crop at its own place across the sensor
        kinds.append(light_kind(split, i))
        preds = {}
        for v, rec in recs.items():
            p = rec(coded[0], uncoded[0])  # told the nominal PSF, whatever made the captures
            preds[v] = p.numpy() if isinstance(p, torch.Tensor) else p
            rows[v].append(metrics_for(task, preds[v], target[0].numpy()))
        if example is None:
            example = (coded[0].numpy(), uncoded[0].numpy(), target[0].numpy(), preds)
    digest = split_digest(task)
    result = {"task": task, "split": split, "images": images, "seed": SPLIT_SEEDS[split], "size_px": size,
              "conditions": cond.describe() if cond is not None else {"name": "clean"},
              "noise": f"Poisson–Gaussian, {sensor.describe(with_response=False)}" if sensor.entry(False)
              else "default (Poisson–Gaussian)", **sensor.entry(task == "hyperspectral"),
              "rows": {v: mean_metrics(rs) for v, rs in rows.items()},
              "weights": {v: {"steps": r.meta["training"]["steps"], "wall_time_s": r.meta["training"]["wall_time_s"],
                              "lr_schedule": r.meta["training"].get("schedule", "constant"),
                              "trained_under": _trained_under(r.meta),
                              "for_this_design": not r.meta.get("other_design", False),
                              **({"for_this_sensor": False} if r.meta.get("other_sensor") else {}),
                              "splits": _splits_state(r.meta, digest)}
                          for v, r in recs.items()}}
    result["per_image"] = {"light": kinds if task == "hyperspectral" else None, "rows": rows}  # for intervals
    if task == "hyperspectral":
        result["by_light"] = {k: {v: mean_metrics([r for r, kk in zip(rs, kinds) if kk == k]) for v, rs in rows.items()}
                              for k in ("in-library", "out-of-library") if k in kinds}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "metrics.json", result)
    _figure(out / "examples.png", task, *example)
    return result


def _splits_state(meta: dict, digest: str) -> str:
    """Whether a network was trained on the split definition this evaluation draws its scenes from."""
    got = meta.get("splits_sha256")
    if got is None:
        return "not recorded (trained before the weights named their splits)"
    return "the same splits" if got == digest else "ANOTHER split definition: the test scenes may hold training content"


def _trained_under(meta: dict) -> str:
    c = meta.get("training", {}).get("conditions")
    return c.get("train", {}).get("name", "clean") if isinstance(c, dict) else "clean"


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
