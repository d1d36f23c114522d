"""Streak (HDR) task, the paper's Eq. 16–18: a cross-shaped coded PSF through the kernel centre."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from doefab.optics.camera import Camera
from doefab.tasks.base import HALF_LIGHT, Task

__all__ = ["StreakTask"]


@dataclass
class StreakTask(Task):
    """Cross of two streaks (row K//2 and column K//2) of half-length ``arm_px`` pixels.

    Choices the paper leaves open: the streak length. The paper draws the cross across the whole kernel
    (x = R/2, y = R/2); we keep arms of ``arm_px`` = 40 px by default (a 81-px cross, 0.44 mm), long enough to
    spread a saturated highlight over many unsaturated pixels while the kernel stays small enough to design
    at full resolution quickly. The metric band is the cross's arms widened by ``band_px`` = 1 px each side
    (DESIGN: "within 1 px of the target cross"), without the (2·band_px + 1)² square where the two arms cross:
    light there is the highlight itself, not a streak. A plain (flat) half focuses to a spot on that centre,
    and so does the zero order an etch-depth error leaks; counted, they would score as streak light (a flat
    coded half 0.96 on the committed HDR camera against its design's 0.87). ``loss_kind``: ``"band"`` (light
    outside the arms, default: it is the metric) or ``"l1"`` (the paper's Eq. 18, L1 to the cross scaled to sum
    0.5).
    """

    kernel_size: int = 95
    arm_px: int = 40
    band_px: int = 1
    name: str = field(default="streak", init=False)
    preset: str = field(default="hdr", init=False)
    metric_name: str = field(default="fraction of coded light on the cross's arms (within 1 px, off its centre)",
                             init=False)
    default_iterations: int = field(default=60, init=False)
    default_lr: float = field(default=0.02, init=False)
    default_batch: int = field(default=0, init=False)
    RANGES = {**Task.RANGES, "arm_px": (1, 2047, True, "sensor pixels"), "band_px": (0, 64, True, "sensor pixels")}

    PATTERN_HINT = "lower arm_px (a scene's design.streak_arm_px)"
    METRIC_WIDTH = ("band_px", "design.streak_band_px")  # the metric's half-width (sensor px): field, scene key

    def pattern_reach_px(self, camera: Camera) -> float:
        """The arms, the metric's band and 1 px (``Task.pattern_reach_px``)."""
        return float(self.arm_px + self.band_px + 1)

    def _cross(self, width: int) -> torch.Tensor:
        k, c = self.kernel_size, self.kernel_size // 2
        i = torch.arange(k)
        near = (i - c).abs() <= width
        inside = (i - c).abs() <= self.arm_px + width
        rows = near[:, None] & inside[None, :]
        cols = inside[:, None] & near[None, :]
        return (rows | cols).double()

    def targets(self, camera: Camera) -> torch.Tensor:
        ind = self._cross(0)
        t = ind * (HALF_LIGHT / ind.sum())
        return t.expand(1, len(self.wavelengths(camera)), -1, -1)

    def band_masks(self, camera: Camera) -> torch.Tensor:
        """The arms: the cross widened by ``band_px`` each side, less the square where its two bands overlap."""
        c, w = self.kernel_size // 2, self.band_px
        arms = self._cross(w)
        lo = max(c - w, 0)  # a band wider than the window: the whole window is its centre (no arms)
        arms[lo:c + w + 1, lo:c + w + 1] = 0.0
        return arms.expand(1, len(self.wavelengths(camera)), -1, -1)

    def init_height(self, camera: Camera, rng: np.random.Generator) -> np.ndarray:
        """Two cylindrical lenses in interleaved horizontal stripes: one spreads light along x, one along y.

        A quadratic phase in x alone turns a point into a line along x whose length is set by its power;
        the arm length fixes that power (defocus giving a geometric half-length of ``arm_px`` pixels).
        """
        n, a = camera.doe_pixels, camera.doe_pitch
        c = (np.arange(n) - (n - 1) / 2) * a
        xx, yy = np.meshgrid(c, -c)
        lam = camera.design_wavelength
        h2pi = camera.material.height_2pi(lam)
        half_len = self.arm_px * camera.sensor_pitch
        radius = camera.aperture_diameter / 2
        # geometric: a wavefront curvature 1/R gives a line half-length s·r_max/R; for x the coded half
        # spans r ≤ D/2 in x and y; waves = r² / (2 R λ)
        curv = half_len / (camera.sensor_distance * radius)
        waves_x = xx**2 * curv / (2 * lam)
        waves_y = yy**2 * curv / (2 * lam)
        stripe = (np.floor((yy + radius) / (8 * a)) % 2 == 0)
        waves = np.where(stripe, waves_x, waves_y) + rng.uniform(0, 0.02, size=(n, n))
        return np.mod(waves, 1.0) * h2pi
