"""The paper's metrics (Tables 1–3): HDR RMSE/PSNR (peak 2^8) overall and in highlights, hyperspectral PSNR/SSIM/
SAM (radians), depth MAE/RMSE/log10/δ<1.25."""

from __future__ import annotations

import math

import numpy as np

from doefab.applications import HDR_PEAK, View, application

__all__ = ["hdr_metrics", "spectral_metrics", "depth_metrics", "depth_pixels", "metrics_for", "mean_metrics", "HDR_PEAK",
           "HIGHLIGHT_ABOVE", "DISPLAY", "metric_label", "metric_text"]

HIGHLIGHT_ABOVE = 2.0  # highlight pixels: radiance that saturates the plain half-exposure capture
#: each task's metrics as reports name them: name → (display name, unit as printed: ``Metric.shown_unit``, "" for
#: a ratio, "× clip" for HDR radiance, which is relative: 1 is the plain capture's clip) — a view of
#: ``doefab.applications``' Metric rows
DISPLAY = View(lambda a: {m.name: (m.label, m.shown_unit) for m in a.metrics})
DIGITS = {"dB": 2}  # decimals a report prints per unit (3 for every other)


def _psnr(mse: float, peak: float) -> float:
    return float(10 * np.log10(peak**2 / max(mse, 1e-20)))


def hdr_metrics(pred: np.ndarray, target: np.ndarray) -> dict:
    """[3, H, W] radiance each."""
    err = (pred - target) ** 2
    hl = (target > HIGHLIGHT_ABOVE).any(axis=0)
    mse = float(err.mean())
    out = {"rmse": float(np.sqrt(mse)), "psnr": _psnr(mse, HDR_PEAK)}
    if hl.any():
        mse_h = float(err[:, hl].mean())
        out.update(rmse_highlight=float(np.sqrt(mse_h)), psnr_highlight=_psnr(mse_h, HDR_PEAK))
    else:
        out.update(rmse_highlight=float("nan"), psnr_highlight=float("nan"))
    return out


def spectral_metrics(pred: np.ndarray, target: np.ndarray) -> dict:
    """[C, H, W] spectra each (peak 1 for PSNR and SSIM); SAM in radians, averaged over pixels."""
    from skimage.metrics import structural_similarity

    mse = float(((pred - target) ** 2).mean())
    ssim = float(structural_similarity(target.astype(np.float64), pred.astype(np.float64), data_range=1.0,
                                       channel_axis=0))
    dot = (pred * target).sum(axis=0)
    norms = np.linalg.norm(pred, axis=0) * np.linalg.norm(target, axis=0)
    sam = float(np.mean(np.arccos(np.clip(dot / np.maximum(norms, 1e-12), -1, 1))))
    return {"psnr": _psnr(mse, 1.0), "ssim": ssim, "sam": sam}


def depth_pixels(pred: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel of [H, W] depths (metres): (prediction floored at 1 mm, |error| in metres, whether
    max(p/t, t/p) < 1.25)."""
    p = np.maximum(pred, 1e-3)
    return p, np.abs(p - target), np.maximum(p / target, target / p) < 1.25


def depth_metrics(pred: np.ndarray, target: np.ndarray) -> dict:
    """[H, W] metres each; pixels whose target is NaN (not measured) are left out."""
    known = np.isfinite(target)
    if not known.all():
        pred, target = pred[known], target[known]
    p, err, within = depth_pixels(pred, target)
    return {"mae": float(err.mean()), "rmse": float(np.sqrt((err**2).mean())),
            "log10": float(np.abs(np.log10(p) - np.log10(target)).mean()), "delta125": float(within.mean())}


def metric_label(task: str, name: str) -> str:
    """A metric's column or axis label, e.g. "highlight PSNR (dB)"; an unknown name as it is."""
    display, unit = DISPLAY.get(task, {}).get(name, (name, ""))
    return f"{display} ({unit})" if unit else display


def metric_text(task: str, name: str, value: float, unit: bool = True) -> str:
    """A metric's value with its unit (``unit=False``: without), to the decimals reports print: "29.89 dB",
    "0.387 m", "0.352 rad"; "—" for a value that is not a number."""
    if math.isnan(value):
        return "—"
    u = DISPLAY.get(task, {}).get(name, (name, ""))[1]
    return f"{value:.{DIGITS.get(u, 3)}f}" + (f" {u}" if u and unit else "")


def metrics_for(task: str, pred: np.ndarray, target: np.ndarray) -> dict:
    """{metric: value} of a reconstruction ``pred`` against ``target`` by the application's ``metric_function``
    (``doefab.applications``; units as its ``Metric`` rows print them).

    Example: ``metrics_for("depth", np.full((8, 8), 2.2), np.full((8, 8), 2.0))["mae"]`` → 0.2 (m)."""
    return application(task).function("metric_function")(pred, target)


def mean_metrics(rows: list[dict]) -> dict:
    """Per metric, the mean over images that define it (the highlight metrics of an image without highlights
    are nan); nan if none does."""
    out = {}
    for k in rows[0]:
        v = np.array([r[k] for r in rows], dtype=np.float64)
        v = v[~np.isnan(v)]
        out[k] = float(v.mean()) if v.size else float("nan")
    return out
