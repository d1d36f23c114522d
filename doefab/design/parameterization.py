"""How the optimiser sees a height map: unconstrained phase in waves, wrapped into one 16-level process.

``height = h_2π · frac(θ)`` keeps every height in [0, h_2π) at the design wavelength without a constraint
(gradient 1 almost everywhere). The quantization-aware stage uses a straight-through estimator around
the same rounding the mask export uses (``doefab.fabrication.levels``).
"""

from __future__ import annotations

import torch

from doefab.fabrication.levels import N_LEVELS, quantize_torch
from doefab.optics.camera import Camera

__all__ = ["theta_to_height", "quantize_ste", "isolated_pixel_penalty"]


def theta_to_height(theta: torch.Tensor, camera: Camera) -> torch.Tensor:
    """Heights (metres) in [0, h_2π) from unconstrained θ (waves at the design wavelength)."""
    h2pi = camera.material.height_2pi(camera.design_wavelength)
    return torch.remainder(theta, 1.0) * h2pi


def quantize_ste(height: torch.Tensor, camera: Camera, n_levels: int = N_LEVELS) -> torch.Tensor:
    """Quantized heights forward, identity gradient backward (straight-through estimator)."""
    return height + (quantize_torch(height.detach(), camera, n_levels) - height).detach()


def isolated_pixel_penalty(theta: torch.Tensor, weight_mask: torch.Tensor) -> torch.Tensor:
    """Mean over ``weight_mask`` of how much each pixel differs in phase from its most similar neighbour.

    A pixel whose four neighbours all differ from it (an isolated single-pixel pillar or hole) scores up to
    1; a pixel that matches any neighbour scores 0. Phase differences are circular (θ in waves).
    """
    def diff(a, b):
        return 0.5 * (1.0 - torch.cos(2 * torch.pi * (a - b)))

    t = theta
    big = torch.full_like(t, 1.0)
    up = big.clone()
    up[1:, :] = diff(t[1:, :], t[:-1, :])
    down = big.clone()
    down[:-1, :] = diff(t[:-1, :], t[1:, :])
    left = big.clone()
    left[:, 1:] = diff(t[:, 1:], t[:, :-1])
    right = big.clone()
    right[:, :-1] = diff(t[:, :-1], t[:, 1:])
    score = torch.minimum(torch.minimum(up, down), torch.minimum(left, right))
    return (score * weight_mask).sum() / weight_mask.sum().clamp_min(1.0)
