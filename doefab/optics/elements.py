"""Reference height maps: blank DOE and blazed gratings (full aperture grid, metres)."""

from __future__ import annotations

import numpy as np

from doefab.validate import number_in, wavelength_m
from doefab.errors import DoefabError
from doefab.optics.camera import Camera, require_camera

__all__ = ["blank_height", "blazed_grating_height"]


def blank_height(camera: Camera) -> np.ndarray:
    """(N, N) float64 zeros: a DOE with no structure."""
    camera = require_camera(camera)
    return np.zeros((camera.doe_pixels, camera.doe_pixels), dtype=np.float64)


def blazed_grating_height(camera: Camera, period_pixels: float = 16, n_levels: int | None = None,
                          wavelength: float | None = None, direction: int = +1) -> np.ndarray:
    """Blazed grating along x over the whole grid, heights in [0, h_2π) at ``wavelength``.

    Args:
        period_pixels: grating period Λ in DOE pixels (16 in the paper).
        n_levels: None for the continuous (pixel-sampled) blaze; else a staircase of ``n_levels`` steps
            per period, step heights (N_steps − 1)/N · h_2π (the ideal multi-level blaze).
        wavelength: blaze wavelength, metres (default: the camera's design wavelength).
        direction: +1 deflects the first order toward +x, -1 toward -x.
    Returns:
        (N, N) float64 heights, metres. Pixel j's phase is sampled at its centre for the continuous
        blaze, and equals floor(N_steps · frac(x/Λ)) / N_steps of a wave for the staircase.
    """
    camera = require_camera(camera)
    period_pixels = number_in("period_pixels", period_pixels, 2, 1e6, unit="DOE pixels (not metres)")
    if n_levels is not None:
        n_levels = number_in("n_levels", n_levels, 2, 256, integer=True)
    if isinstance(direction, bool) or direction not in (-1, 1):
        raise DoefabError(f"direction must be +1 or -1, got {direction!r}")
    lam = camera.design_wavelength if wavelength is None else wavelength_m("wavelength", wavelength)
    h2pi = camera.material.height_2pi(lam)
    j = np.arange(camera.doe_pixels, dtype=np.float64)
    if n_levels is None:
        frac = np.mod((j + 0.5) / period_pixels, 1.0)
    else:
        frac = np.floor(np.mod(j / period_pixels, 1.0) * n_levels + 1e-9) / n_levels
    if direction < 0:
        frac = np.mod(-frac, 1.0)
    row = frac * h2pi
    return np.tile(row, (camera.doe_pixels, 1))
