"""How the optimiser sees a height map: unconstrained phase in waves, wrapped into one L-level process.

``height = h_2π · frac(θ)`` keeps every height in [0, h_2π) at the design wavelength without a constraint
(gradient 1 almost everywhere). The quantization-aware stage uses a straight-through estimator around
the same rounding the mask export uses (``doefab.fabrication.levels``).
"""

from __future__ import annotations

import torch

from doefab.fabrication.levels import quantize_torch
from doefab.fabrication.process import DEFAULT_LEVELS
from doefab.optics.camera import Camera

__all__ = ["theta_to_height", "quantize_ste", "isolated_pixel_penalty", "PixelParam", "RadialParam",
           "make_parameterization", "lens_difference_waves", "PARAMETERIZATIONS", "STARTS"]


def theta_to_height(theta: torch.Tensor, camera: Camera) -> torch.Tensor:
    """Heights (metres) in [0, h_2π) from unconstrained θ (waves at the design wavelength)."""
    h2pi = camera.material.height_2pi(camera.design_wavelength)
    return torch.remainder(theta, 1.0) * h2pi


def quantize_ste(height: torch.Tensor, camera: Camera, n_levels: int = DEFAULT_LEVELS) -> torch.Tensor:
    """Quantized heights (nearest of ``n_levels`` levels) forward, identity gradient backward (straight-through
    estimator)."""
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


PARAMETERIZATIONS = ("pixel", "radial")
STARTS = ("task", "lens")


class PixelParam:
    """One free phase (waves) per DOE pixel: θ is the (N, N) map itself."""

    name = "pixel"

    def __init__(self, camera: Camera):
        self.camera = camera

    def waves(self, theta: torch.Tensor) -> torch.Tensor:
        return theta

    def variable_mask(self, coded_mask: torch.Tensor) -> torch.Tensor:
        return coded_mask

    def to(self, device) -> "PixelParam":
        """This parameterisation for θ on ``device`` (it holds no tensor)."""
        return self

    def start(self, task, rng, start: str) -> torch.Tensor:
        if start == "lens":
            return torch.from_numpy(lens_difference_waves(self.camera, task)).float()
        h2pi = self.camera.material.height_2pi(self.camera.design_wavelength)
        return torch.from_numpy(task.init_height(self.camera, rng) / h2pi).float()


class RadialParam:
    """A rotationally symmetric phase profile θ(r) in waves, the authors' released parameterisation.

    ``knots`` values at radii r_j = j·R/(knots − 1), j = 0..knots−1 (R = the aperture radius), linearly
    interpolated to every DOE pixel's centre radius (pixels beyond R, outside the clear aperture, take the last
    knot). The profile is interpolated *unwrapped* and wrapped afterwards (``theta_to_height``), so a steep lens
    phase costs no interpolation error at its 2π jumps. Applied over the whole grid; only the coded half acts.
    Default knot count: one per pixel of ``camera``'s grid along the radius (N/2; the design grid when the design is
    coarsened), which resolves any profile that grid can.
    """

    name = "radial"

    def __init__(self, camera: Camera, knots: int = 0):
        n = camera.doe_pixels
        self.camera = camera
        self.knots = int(knots) if knots else max(2, (n + 1) // 2)
        if self.knots < 2:
            raise ValueError("a radial profile needs at least 2 knots")
        c = (torch.arange(n, dtype=torch.float64) - (n - 1) / 2) * camera.doe_pitch
        r = torch.sqrt(c[None, :] ** 2 + c[:, None] ** 2)
        pos = (r / (camera.aperture_diameter / 2)).clamp(max=1.0) * (self.knots - 1)
        self._i0 = pos.floor().long().clamp(max=self.knots - 2)
        self._w = (pos - self._i0).float()

    def waves(self, theta: torch.Tensor) -> torch.Tensor:
        return theta[self._i0] * (1 - self._w) + theta[self._i0 + 1] * self._w

    def to(self, device) -> "RadialParam":
        """This parameterisation with its interpolation tables on ``device`` (where θ lives)."""
        self._i0, self._w = self._i0.to(device), self._w.to(device)
        return self

    def variable_mask(self, coded_mask: torch.Tensor) -> torch.Tensor:
        return torch.ones(self.knots)

    def radii(self) -> torch.Tensor:
        return torch.linspace(0, self.camera.aperture_diameter / 2, self.knots, dtype=torch.float64)

    def start(self, task, rng, start: str) -> torch.Tensor:
        """The lens-difference profile (``start="lens"``, default for radial) or flat (``"task"``: a pixel
        task start has no radial form)."""
        if start == "lens":
            return torch.from_numpy(lens_difference_waves(self.camera, task, self.radii().numpy() ** 2)).float()
        return torch.zeros(self.knots)


def _extra_power(camera: Camera, task) -> float:
    """Optical power (1/m) that refocuses the coded half from the camera's focus to the task's farthest depth."""
    import math

    far = max(task.depths(camera))
    focus = camera.focus_distance
    return (0.0 if math.isinf(focus) else 1.0 / focus) - (0.0 if math.isinf(far) else 1.0 / far)


def lens_difference_waves(camera: Camera, task, r2=None):
    """Unwrapped phase (waves) of the thin lens that refocuses the coded half to the task's farthest depth (the
    paper's half-ring starts sharp at 5 m, ring radius 0, and blurs towards the near planes), at squared radii
    ``r2`` (m²; default the (N, N) DOE pixel centres)."""
    import numpy as np

    if r2 is None:
        c = (np.arange(camera.doe_pixels) - (camera.doe_pixels - 1) / 2) * camera.doe_pitch
        r2 = c[None, :] ** 2 + c[:, None] ** 2
    # a point at z arrives with path r²/2z; in focus it would be r²/2z_f: the DOE adds r²/2·(1/z_f − 1/z_far)
    return r2 * _extra_power(camera, task) / (2 * camera.design_wavelength)


def make_parameterization(name: str, camera: Camera, knots: int = 0):
    from doefab.errors import DoefabError

    if name == "pixel":
        if knots:
            raise DoefabError("--knots applies to the radial parameterisation only")
        return PixelParam(camera)
    if name == "radial":
        if knots and knots < 2:
            raise DoefabError(f"a radial profile needs at least 2 knots, got {knots}")
        return RadialParam(camera, knots)
    raise DoefabError(f"unknown parameterisation {name!r}: choose one of {PARAMETERIZATIONS}")
