"""Grating (hyperspectral) task, the paper's Eq. 21–22: one first-order spot per band."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.optics.camera import Camera
from doefab.optics.elements import blazed_grating_height
from doefab.tasks.base import HALF_LIGHT, Task

__all__ = ["GratingTask", "grating_spot_px", "period_for_spread", "period_for_reach"]


def grating_spot_px(camera: Camera, wavelength: float, period: float) -> float:
    """Sensor position (pixels from the axis, +x) of the first order: s·tan(asin(λ/Λ)) / p (Eq. 21 erratum).

    ``period`` Λ in metres.
    """
    return camera.sensor_distance * math.tan(math.asin(wavelength / period)) / camera.sensor_pitch


def period_for_spread(camera: Camera, lam_min: float, lam_max: float, spread_px: float) -> float:
    """The grating period Λ (m) whose first orders of ``lam_min`` and ``lam_max`` (m) land ``spread_px`` sensor
    pixels apart (``grating_spot_px``; the spread falls as Λ grows, so one root above ``lam_max``).

    Example: a 4.4 mm sensor distance with 1.4 µm pixels spreads 400–700 nm over 30 px at Λ ≈ 31.4 µm:
    ``period_for_spread(cam, 400e-9, 700e-9, 30.0)``.
    """
    from scipy.optimize import brentq

    def spread(period: float) -> float:
        return grating_spot_px(camera, lam_max, period) - grating_spot_px(camera, lam_min, period) - spread_px

    lo, hi = lam_max * (1 + 1e-9), lam_max * 1e6
    return float(brentq(spread, lo, hi, xtol=1e-15, rtol=1e-12)) if spread(lo) > 0 > spread(hi) else math.nan


def period_for_reach(camera: Camera, lam_max: float, reach_px: float) -> float:
    """The shortest grating period Λ (m), to 0.01 µm, whose first order of ``lam_max`` (m) lands at most
    ``reach_px`` sensor pixels off axis (``grating_spot_px``): λ / sin(atan(reach · p / s)) rounded up, and up
    again while the rounded period, as a scene writes it in µm, lands beyond the reach; NaN for no reach.

    Example: with the sensor 16 mm behind the lens (``Camera(sensor_distance=16e-3, sensor_pitch=1.55e-6)``),
    700 nm lands within 92 px at Λ ≥ 78.55 µm: ``period_for_reach(cam, 700e-9, 92.0)`` → 7.855e-05.
    """
    if reach_px <= 0:
        return math.nan
    exact = lam_max / math.sin(math.atan(reach_px * camera.sensor_pitch / camera.sensor_distance))
    um = math.ceil(exact * 1e8) / 100
    while grating_spot_px(camera, lam_max, um * 1e-6) > reach_px:
        um = round(um + 0.01, 2)
    return um * 1e-6


@dataclass
class GratingTask(Task):
    """Spots at the grating's first order for 31 bands 400–700 nm, Λ = 16 DOE pixels.

    The metric box for band λ is the 3 × 3 pixels around the pixel that holds the spot centre. Kernel:
    the 700 nm spot lies 75 px off axis, so K = 191 keeps every box inside with margin. ``loss_kind``:
    ``"window"`` (default: 1 − mean box fraction + (1 − soft-min over bands), which raises the worst band
    too), ``"band"`` (1 − mean box fraction) or ``"l1"`` (the paper's Eq. 22, L1 to a Dirac per band — it can
    lower the metric, see the README).
    """

    kernel_size: int = 191
    period_pixels: float = 16.0
    period_m: float | None = None  # set by bind(): period_pixels × the preset's DOE pitch
    n_bands: int = 31
    box_px: int = 1  # the metric box of each band: (2·box_px + 1)² pixels around its first order
    loss_kind: str = "window"
    name: str = field(default="grating", init=False)
    preset: str = field(default="hyperspectral", init=False)
    metric_name: str = field(default="fraction of coded light in the 3x3 box of each band's first order", init=False)
    default_iterations: int = field(default=300, init=False)
    default_lr: float = field(default=0.01, init=False)
    default_batch: int = field(default=8, init=False)
    RANGES = {**Task.RANGES, "period_pixels": (2, 1e6, False, "DOE pixels"), "period_m": (1e-7, 1e-2, False, "m"),
              "n_bands": (1, 1000, True, "bands"), "box_px": (0, 64, True, "sensor pixels")}

    def wavelengths(self, camera: Camera) -> tuple[float, ...]:
        if self.wavelengths_m:
            return tuple(self.wavelengths_m)
        return tuple(float(v) for v in np.linspace(400e-9, 700e-9, self.n_bands))

    def spot_pixels(self, camera: Camera) -> list[int]:
        """Column offset (pixels from the centre) of the pixel holding each band's spot centre."""
        return [int(round(grating_spot_px(camera, lam, self.period(camera)))) for lam in self.wavelengths(camera)]

    def bind(self, camera: Camera) -> None:
        if self.period_m is None:
            self.period_m = self.period_pixels * camera.doe_pitch
        lam = max(self.wavelengths(camera))
        if self.period_m <= lam:  # sin θ = λ / Λ: no first order
            raise DoefabError(f"GratingTask: a period of {self.period_m * 1e6:g} µm sends no first order at "
                              f"{lam * 1e9:g} nm (sin θ = λ / Λ needs Λ > λ): set period_m or period_pixels (a "
                              f"scene's design.grating_period_um) longer, e.g. {16 * camera.doe_pitch * 1e6:g} µm "
                              f"(16 DOE pixels)")

    PATTERN_HINT = "a longer period_m (a scene's design.grating_period_um)"

    def first_order_px(self, camera: Camera) -> float:
        """How far off axis (sensor px) the farthest band's first order lands (``grating_spot_px``)."""
        return max(abs(grating_spot_px(camera, lam, self.period(camera))) for lam in self.wavelengths(camera))

    def pattern_reach_px(self, camera: Camera) -> float:
        """The farthest band's first order, its metric box and 2 px (``Task.pattern_reach_px``)."""
        return self.first_order_px(camera) + self.box_px + 2

    def window_px(self, far_px: float) -> int:
        """The odd PSF window (px) that holds a first order ``far_px`` off axis with its metric box and a 2 px
        margin: what ``optics.kernel_px`` must reach."""
        return 2 * math.ceil(far_px + self.box_px + 3) + 1

    def period(self, camera: Camera) -> float:
        """Grating period Λ in metres."""
        return self.period_m if self.period_m is not None else self.period_pixels * camera.doe_pitch

    def _masks(self, camera: Camera, width: int) -> torch.Tensor:
        k, c = self.kernel_size, self.kernel_size // 2
        out = torch.zeros(1, len(self.wavelengths(camera)), k, k, dtype=torch.float64)
        for w, off in enumerate(self.spot_pixels(camera)):
            col = c + off
            out[0, w, c - width:c + width + 1, col - width:col + width + 1] = 1.0
        return out

    def targets(self, camera: Camera) -> torch.Tensor:
        return self._masks(camera, 0) * HALF_LIGHT

    def band_masks(self, camera: Camera) -> torch.Tensor:
        return self._masks(camera, self.box_px)

    def init_height(self, camera: Camera, rng: np.random.Generator) -> np.ndarray:
        """The 16-pixel blazed grating (the paper's § 4.4), blazed at the design wavelength."""
        return blazed_grating_height(camera, self.period(camera) / camera.doe_pitch)
