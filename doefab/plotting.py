"""Figures people look at: PSFs and height maps (matplotlib, Agg backend, imported only when drawing)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_psf_grid", "plot_height", "psf_pair_figure", "depth_label", "core_window", "design_psf_figure",
           "save_figure"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Save ``fig`` cropped to everything drawn (``bbox_inches="tight"``: no label falls outside the image) and
    close it."""
    path = Path(path)
    fig.savefig(path, dpi=dpi, bbox_inches="tight", pad_inches=0.05)
    _plt().close(fig)
    return path


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
    return save_figure(fig, path)


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
    return save_figure(fig, path)


def depth_label(z: float) -> str:
    """``"z = 2 m"``, or ``"z = ∞"`` for a point at infinity."""
    import math

    return f"z = {z:g} m" if math.isfinite(z) else "z = ∞"


def core_window(images, energy: float = 0.995, minimum: int = 15) -> int:
    """Half-width (pixels) of the centred square holding ``energy`` of every image's light in the window."""
    best = minimum
    for img in images:
        k = img.shape[-1]
        c = k // 2
        total = float(img.sum())
        if total <= 0:
            continue
        for r in range(minimum, c + 1):
            if float(img[c - r:c + r + 1, c - r:c + r + 1].sum()) >= energy * total:
                best = max(best, r)
                break
        else:
            best = c
    return best


def psf_pair_figure(path: str | Path, coded: np.ndarray, uncoded: np.ndarray, depths, sensor_pitch: float,
                    title: str = "", log: bool = True) -> Path:
    """Coded (left) and uncoded (right) PSFs, one row per depth, on ONE colour scale, cropped to the core.

    Args:
        coded, uncoded: [n_depths, n_wavelengths, K, K] fractions of the aperture's light per pixel
            (summed over wavelengths for display).
    """
    from matplotlib.colors import LogNorm, Normalize

    plt = _plt()
    c = coded.sum(axis=1)
    u = uncoded.sum(axis=1)
    k = c.shape[-1]
    r = core_window(list(c) + list(u))
    m = k // 2
    sl = slice(m - r, m + r + 1)
    c, u = c[:, sl, sl], u[:, sl, sl]
    vmax = float(max(c.max(), u.max()))
    norm = LogNorm(vmin=max(vmax * 1e-5, 1e-12), vmax=vmax) if log else Normalize(vmin=0, vmax=vmax)
    nd = len(depths)
    fig, axes = plt.subplots(nd, 2, figsize=(6.6, 3.0 * nd + 0.6), squeeze=False, layout="constrained")
    half = (r + 0.5) * sensor_pitch * 1e6
    im = None
    for zi, z in enumerate(depths):
        for col, (name, img) in enumerate((("coded (DOE half)", c[zi]), ("uncoded (plain half)", u[zi]))):
            ax = axes[zi, col]
            im = ax.imshow(np.maximum(img, norm.vmin) if log else img, extent=(-half, half, -half, half),
                           cmap="inferno", norm=norm, origin="upper", interpolation="nearest")
            ax.set_title(f"{name}, {depth_label(z)}", fontsize=8)
            ax.set_xlabel("x on sensor (µm)", fontsize=7)
            ax.set_ylabel("y on sensor (µm)", fontsize=7)
            ax.tick_params(labelsize=6)
    cb = fig.colorbar(im, ax=axes, shrink=0.8)
    cb.set_label("fraction of the aperture's light per pixel" + (" (log scale)" if log else ""), fontsize=7)
    cb.ax.tick_params(labelsize=6)
    fig.suptitle(title + (" — " if title else "") + "both halves on one colour scale", fontsize=9)
    return save_figure(fig, path)


def design_psf_figure(path: str | Path, d, psf, targets, panels_max: int = 4) -> Path:
    """Up to ``panels_max`` (depth, band) entries of a design's coded PSFs (``psf``: [D, W, K, K]) beside their
    targets, on a log scale: a grating's orders and a streak's arms are a few bright pixels in a large window,
    invisible on a linear one."""
    picks = [(z, w) for z in range(psf.shape[0]) for w in range(psf.shape[1])]
    picks = [picks[i] for i in np.linspace(0, len(picks) - 1, min(panels_max, len(picks))).round().astype(int)]
    panels = []
    for z, w in picks:
        lab = f"{d.wavelengths[w] * 1e9:.0f} nm, {depth_label(d.depths[z])}"
        panels += [(f"target, {lab}", targets[z, w]), (f"{d.n_levels}-level design, {lab}", psf[z, w])]
    return plot_psf_grid(path, panels, d.camera.sensor_pitch, ncols=2, log=True,
                         suptitle=f"{d.task}: target (left) and fabricated {d.n_levels}-level design (right), log scale")
