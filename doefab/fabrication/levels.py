"""The level ↔ height convention of a multi-level DOE, kept in one place (DESIGN-NOTES, Conventions).

Heights are heights of material above the deepest etch; level k of L (L = 2, 4, 8, 16 or 32 for M = log2 L
binary masks; 16 and 4 masks by default) means height k·d with d = h_2π / L and h_2π = λ_design / (n(λ_design) − 1).
Quantization rounds to the nearest level (not flooring) after wrapping the height into one 2π period; the mask
export and the simulation use these same functions. The simulation accepts any L from 2 to 256 (the quantization
study); what a fab makes is ``doefab.fabrication.process``.
"""

from __future__ import annotations

import hashlib

import numpy as np
import torch

from doefab.validate import heights, number_in
from doefab.errors import DoefabError
from doefab.fabrication.process import DEFAULT_LEVELS
from doefab.optics.camera import Camera, require_camera

__all__ = ["level_step", "material_level_step", "levels_to_height", "quantize_levels", "quantize_height", "quantize_torch", "wrap_height",
           "levels_sha256"]


def level_step(camera: Camera, n_levels: int = DEFAULT_LEVELS) -> float:
    """Height of one level d (metres) = h_2π(design wavelength) / n_levels.

    Example:

        >>> import doefab
        >>> round(doefab.level_step(doefab.Camera(), 16) * 1e9, 2)  # nm: 550 nm / (n − 1) / 16 in fused silica
        74.74
    """
    camera = require_camera(camera)
    return material_level_step(camera.material, camera.design_wavelength, n_levels)


def material_level_step(material, design_wavelength: float, n_levels: int = DEFAULT_LEVELS) -> float:
    """Height of one level d (metres) of ``material`` (a ``doefab.Material``) at ``design_wavelength`` (m)."""
    number_in("n_levels", n_levels, 2, 256, integer=True)  # level maps are uint8
    return material.height_2pi(design_wavelength) / n_levels


def wrap_height(height, camera: Camera):
    """Height modulo h_2π at the design wavelength (same type as input), in [0, h_2π)."""
    h2pi = require_camera(camera).material.height_2pi(camera.design_wavelength)
    if isinstance(height, torch.Tensor):
        return torch.remainder(height, h2pi)
    return np.mod(np.asarray(height, dtype=np.float64), h2pi)


def quantize_levels(height, camera: Camera, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """Nearest level index (uint8, 0..n_levels-1) of each height (metres), after wrapping into one 2π period.

    A height within half a step below h_2π rounds to level n_levels ≡ 0 (it is the same phase).

    Example:

        >>> import numpy as np, doefab
        >>> doefab.quantize_levels(np.array([0.0, 0.6e-6, 1.19e-6]), doefab.Camera(), 16).tolist()  # 1.19 µm ≈ 2π
        [0, 8, 0]
    """
    h = height.detach().cpu().numpy() if isinstance(height, torch.Tensor) else np.asarray(height, np.float64)
    heights("height", h)
    d = level_step(camera, n_levels)
    k = np.rint(np.mod(h, d * n_levels) / d).astype(np.int64) % n_levels
    return k.astype(np.uint8)


def quantize_torch(height: torch.Tensor, camera: Camera, n_levels: int = DEFAULT_LEVELS) -> torch.Tensor:
    """The rule of :func:`quantize_levels` on a torch tensor (for the quantization-aware design stage).

    Returns heights (metres) ``d · (round(wrap(h) / d) mod n_levels)``; a test checks that it equals
    ``levels_to_height(quantize_levels(h))`` exactly on random heights.
    """
    d = level_step(camera, n_levels)
    k = torch.remainder(torch.round(torch.remainder(height, d * n_levels) / d), n_levels)
    return k * d


def levels_to_height(levels, camera: Camera, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """Height map (float64 metres) of a level map: level k → k·d.

    Example:

        >>> import numpy as np, doefab
        >>> doefab.levels_to_height(np.array([[0, 1, 15]], np.uint8), doefab.Camera(), 16).round(12).tolist()  # metres
        [[0.0, 7.4743e-08, 1.121141e-06]]
    """
    lv = np.asarray(levels)
    if lv.dtype.kind not in "iu":
        raise DoefabError(f"levels must be an integer array, got dtype {lv.dtype}")
    if lv.size and (lv.min() < 0 or lv.max() >= n_levels):
        raise DoefabError(f"levels must lie in 0..{n_levels - 1}, found {lv.min()}..{lv.max()}")
    return lv.astype(np.float64) * level_step(camera, n_levels)


def quantize_height(height, camera: Camera, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """Height map rounded to the nearest of ``n_levels`` levels (float64 metres).

    Example:

        >>> import numpy as np, doefab
        >>> (doefab.quantize_height(np.array([0.08e-6, 0.5e-6]), doefab.Camera(), 16) * 1e9).round(1).tolist()  # nm
        [74.7, 523.2]
    """
    return levels_to_height(quantize_levels(height, camera, n_levels), camera, n_levels)


def levels_sha256(levels: np.ndarray) -> str:
    """SHA-256 (hex) of the C-ordered uint8 level map (the checksum in design.json and manifest.json)."""
    return hashlib.sha256(np.ascontiguousarray(levels, dtype=np.uint8).tobytes()).hexdigest()
