"""Height maps: the reference ones (blank DOE, blazed gratings; full aperture grid, metres), and a given one
validated as a tensor (``as_height_tensor``)."""

from __future__ import annotations

import numpy as np

from doefab.validate import full_precision, heights, number_in, wavelength_m
from doefab.errors import DoefabError
from doefab.optics.camera import Camera, require_camera

__all__ = ["blank_height", "blazed_grating_height", "as_height_tensor"]


def blank_height(camera: Camera) -> np.ndarray:
    """(N, N) float64 zeros: a DOE with no structure.

    Example:

        >>> import doefab
        >>> h = doefab.blank_height(doefab.Camera(doe_pixels=64, doe_pitch=135e-6))
        >>> h.shape, float(h.max())
        ((64, 64), 0.0)
    """
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

    Example:

        >>> import numpy as np, doefab
        >>> cam = doefab.Camera(doe_pixels=64, doe_pitch=135e-6)
        >>> h = doefab.blazed_grating_height(cam, 16, n_levels=4)  # 16 DOE pixels per period, 4 steps
        >>> len(np.unique(h)), round(float(h.max()) * 1e9, 1)  # nm: 3/4 of the 2π height at 550 nm
        (4, 896.9)
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


def as_height_tensor(height, camera: Camera, name: str = "height", dtype=None):
    """Validate a height map (metres, shape (N, N) of the camera's DOE grid) and return it as a tensor.

    Tensors keep their autograd graph; numpy arrays are converted. ``dtype``: the tensor's (None: float32).
    """
    import torch

    n = camera.doe_pixels
    full_precision(name, height)  # before any conversion: float16 heights are already rounded
    if isinstance(height, torch.Tensor):
        t = height
    else:
        try:
            arr = np.asarray(height)
        except Exception:  # noqa: BLE001 - anything that is not array-like
            raise DoefabError(f"{name} must be an (N, N) array of heights in metres") from None
        if arr.dtype.kind not in "fiu":
            raise DoefabError(f"{name} must be a real numeric array of heights in metres, got dtype {arr.dtype}")
        t = torch.from_numpy(np.ascontiguousarray(arr, dtype=np.float64))
    if t.is_complex() or not (t.is_floating_point() or t.dtype in (torch.int32, torch.int64, torch.uint8)):
        raise DoefabError(f"{name} must hold real heights in metres, got dtype {t.dtype}")
    if tuple(t.shape) != (n, n):
        raise DoefabError(
            f"{name} has shape {tuple(t.shape)} but the camera's DOE grid is ({n}, {n}); resample it or set "
            f"Camera.doe_pixels")
    heights(name, t)
    return t.to(torch.float32 if dtype is None else dtype)
