"""Half-ring (depth) task, the paper's Eq. 25–26: a semicircle whose radius encodes depth."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from doefab.optics.camera import Camera
from doefab.tasks.base import HALF_LIGHT, Task

__all__ = ["HalfRingTask"]


@dataclass
class HalfRingTask(Task):
    """Semicircle whose radius encodes depth, for points at 1–5 m in 0.25 m steps.

    Ring laws (``ring_law``):

    - ``"seed"`` (default, for comparison with the paper): r = 25 − 5z pixels, linear in depth (the paper's Eq. 25):
      20, 15, 10, 5, 0 px at 1–5 m.
    - ``"defocus"``: r linear in *inverse* depth between the nearest and the farthest plane,
      r = r_near · (1/z − 1/z_far) / (1/z_near − 1/z_far) with r_near = the paper's radius at z_near (20 px).
      A defocused (half-)aperture blurs to a radius ∝ |1/z − 1/z_sharp|, so a phase plate that makes the coded
      half sharp at z_far follows this law at every depth at once; the paper's linear law asks for a
      non-physical radius–depth relation that no single plate meets at all depths (the optimiser then
      trades depths against each other).

    Choices: the semicircle opens toward +x (the arc lies on the x ≤ 0 side, ``side = -1``), the side of
    the coded half, where a plain defocused half-aperture already puts its blur for near points; ``side``
    flips it. K = 63 holds the largest ring (20 px at 1 m) with margin. The metric band is every pixel
    within δ = 1 px of the arc (Eq. 26's mask complement). Loss: ``"window"`` by default (Eq. 26 made
    window-independent, 1 − in-band fraction, so light thrown outside the window is penalised too, plus the
    same for the worst depth through a soft minimum: Eq. 26's plain sum let the worst depth stay near 0).
    """

    kernel_size: int = 63
    delta_px: float = 1.0
    side: int = -1
    z_min: float = 1.0
    z_max: float = 5.0
    z_step: float = 0.25
    loss_kind: str = "window"
    ring_law: str = "seed"
    planes_m: tuple | None = None  # explicit depth planes (metres); None: z_min to z_max every z_step
    ring_max_px: float | None = None  # ring radius at the nearest plane; None: the paper's 25 − 5·z_min px
    name: str = field(default="half-ring", init=False)
    preset: str = field(default="depth", init=False)
    metric_name: str = field(default="fraction of coded light within 1 px of the half-ring", init=False)
    default_iterations: int = field(default=600, init=False)
    default_lr: float = field(default=0.03, init=False)
    default_batch: int = field(default=8, init=False)
    RANGES = {**Task.RANGES, "delta_px": (0.01, 100, False, "sensor pixels"), "z_min": (0.01, 1e4, False, "m"),
              "z_max": (0.01, 1e4, False, "m"), "z_step": (1e-4, 1e4, False, "m"),
              "ring_max_px": (0.0, 2047, False, "sensor pixels")}

    def depths(self, camera: Camera) -> tuple[float, ...]:
        if self.planes_m:
            return tuple(self.planes_m)
        n = int(round((self.z_max - self.z_min) / self.z_step)) + 1
        return tuple(float(self.z_min + i * self.z_step) for i in range(n))

    RING_LAWS = ("seed", "defocus")

    def __post_init__(self):
        from doefab.errors import DoefabError

        super().__post_init__()
        if self.planes_m is not None:
            from doefab.validate import depths, repeated

            planes = depths(self.planes_m)
            if len(planes) < 2 or not all(0 < z < float("inf") for z in planes):
                raise DoefabError(f"planes_m must hold at least two depths in metres, all finite (a depth design's "
                                  f"planes are at finite distances, no \"inf\"), got {self.planes_m!r}")
            if twice := repeated(planes):
                raise DoefabError(f"planes_m holds {twice} m more than once: list each depth plane once")
            self.planes_m = tuple(sorted(planes))
            self.z_min, self.z_max = self.planes_m[0], self.planes_m[-1]
        if not self.z_min < self.z_max:
            raise DoefabError(f"z_min {self.z_min} m must be below z_max {self.z_max} m")
        if self.side not in (-1, 1):
            raise DoefabError(f"side must be -1 or +1, got {self.side!r}")
        if self.ring_law not in self.RING_LAWS:
            raise DoefabError(f"unknown ring law {self.ring_law!r}: choose one of {self.RING_LAWS}")

    PATTERN_HINT = "a smaller ring_max_px (a scene's design.ring_max_px)"
    METRIC_WIDTH = ("delta_px", "design.ring_width_px")  # the metric's half-width (sensor px): field, scene key
    RADIAL_TARGET = True  # half rings about the axis: a radial profile on the half aperture forms them

    def pattern_reach_px(self, camera: Camera) -> float:
        """The largest ring, its metric's half-width and 1 px (``Task.pattern_reach_px``)."""
        return max(self.radius_px(z) for z in self.depths(camera)) + self.delta_px + 1

    def radius_px(self, z: float) -> float:
        """Target ring radius in pixels at depth z (metres), by the task's ring law."""
        r_near = self.ring_max_px if self.ring_max_px is not None else max(25.0 - 5.0 * self.z_min, 0.0)
        if self.ring_law == "defocus":
            return r_near * (1.0 / z - 1.0 / self.z_max) / (1.0 / self.z_min - 1.0 / self.z_max)
        if self.ring_max_px is None:
            return max(25.0 - 5.0 * z, 0.0)
        return r_near * (self.z_max - z) / (self.z_max - self.z_min)



    def distance_to_arc(self, r: float) -> np.ndarray:
        """(K, K) distance in pixels from each pixel centre to the semicircle of radius r."""
        k, c = self.kernel_size, self.kernel_size // 2
        i = np.arange(k) - c
        x = i[None, :].astype(float)
        y = -i[:, None].astype(float)
        rho = np.hypot(x, y)
        on_side = x * self.side >= 0
        d_arc = np.abs(rho - r)
        d_end = np.minimum(np.hypot(x, y - r), np.hypot(x, y + r))
        return np.where(on_side, d_arc, d_end)

    def band_masks(self, camera: Camera) -> torch.Tensor:
        masks = [torch.from_numpy((self.distance_to_arc(self.radius_px(z)) <= self.delta_px + 1e-9).astype(float))
                 for z in self.depths(camera)]
        m = torch.stack(masks)[:, None]
        return m.expand(-1, len(self.wavelengths(camera)), -1, -1)

    def targets(self, camera: Camera) -> torch.Tensor:
        tg = []
        for z in self.depths(camera):
            ring = (self.distance_to_arc(self.radius_px(z)) <= 0.5).astype(float)
            tg.append(torch.from_numpy(ring * HALF_LIGHT / ring.sum()))
        return torch.stack(tg)[:, None].expand(-1, len(self.wavelengths(camera)), -1, -1)

    def init_height(self, camera: Camera, rng: np.random.Generator) -> np.ndarray:
        """A weak diffractive lens that moves the coded half's focus to where the ring is a point (5 m).

        With the camera focused at 3.5 m, the coded half needs extra power 1/3.5 − 1/5 m⁻¹ to be sharp at 5 m
        (ring radius 0); at nearer depths it then blurs on the x ≤ 0 side as the target asks.
        """
        n, a = camera.doe_pixels, camera.doe_pitch
        c = (np.arange(n) - (n - 1) / 2) * a
        xx, yy = np.meshgrid(c, -c)
        lam = camera.design_wavelength
        z_point = self.z_max
        power = (0.0 if math.isinf(camera.focus_distance) else 1.0 / camera.focus_distance) - 1.0 / z_point
        waves = (xx**2 + yy**2) * power / (2 * lam)
        waves = waves + rng.uniform(0, 0.02, size=(n, n))
        return np.mod(waves, 1.0) * camera.material.height_2pi(lam)
