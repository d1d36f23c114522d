"""Figures people look at: PSFs and height maps (matplotlib, Agg backend, imported only when drawing)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_psf_grid", "plot_height"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_psf_grid(path: str | Path, panels: list[tuple[str, np.ndarray]], sensor_pitch: float, ncols: int = 3,
                  log: bool = True, suptitle: str = "") -> Path:
    """Save a grid of PSF images (each (K, K), rows = y with row 0 at the top) with µm axes."""
    plt = _plt()
    n = len(panels)
    ncols = min(ncols, n)
    nrows = (n + ncols - 1) // ncols
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.2 * ncols, 3.0 * nrows), squeeze=False)
    for ax, (title, img) in zip(axes.flat, panels):
        k = img.shape[0]
        half = k / 2 * sensor_pitch * 1e6
        shown = np.log10(np.maximum(img, img.max() * 1e-6)) if log else img
        im = ax.imshow(shown, extent=(-half, half, -half, half), cmap="inferno", origin="upper")
        ax.set_title(title, fontsize=8)
        ax.set_xlabel("x (µm)", fontsize=7)
        ax.set_ylabel("y (µm)", fontsize=7)
        ax.tick_params(labelsize=6)
        cb = fig.colorbar(im, ax=ax, fraction=0.046)
        cb.ax.tick_params(labelsize=6)
        cb.set_label("log10 energy / pixel" if log else "energy / pixel", fontsize=6)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if suptitle:
        fig.suptitle(suptitle, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_height(path: str | Path, height: np.ndarray, pitch: float, title: str = "") -> Path:
    """Save a height map (metres; rows = y, row 0 at the top) in nm with mm axes."""
    plt = _plt()
    n = height.shape[0]
    half = n / 2 * pitch * 1e3
    fig, ax = plt.subplots(figsize=(4.5, 4))
    im = ax.imshow(height * 1e9, extent=(-half, half, -half, half), cmap="viridis", origin="upper",
                   interpolation="nearest")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(title, fontsize=9)
    fig.colorbar(im, ax=ax, label="height (nm)")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
