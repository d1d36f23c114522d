"""Grating (hyperspectral) task, the paper's Eq. 21–22: one first-order spot per band."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.optics.camera import Camera
from doefab.optics.elements import blazed_grating_height
from doefab.tasks.base import HALF_LIGHT, Task, least_window

__all__ = ["GratingTask", "grating_spot_px", "mapping_error_px", "period_for_mapping", "period_for_spread",
           "period_for_reach", "MAX_MAPPING_PX"]


MAX_MAPPING_PX = 0.5  # how far (sensor px) the model may put a first order from where a rectilinear lens sends it


def grating_spot_px(camera: Camera, wavelength: float, period: float) -> float:
    """Sensor position (pixels from the axis, +x) where the PSF model puts the first order: s·λ/Λ / p.

    The model is Fraunhofer (a sensor position is linear in the direction sine), so the design's targets and metric
    boxes sit here; a rectilinear lens sends the order to s·tan(asin(λ/Λ)) / p (Eq. 21 erratum), which
    ``mapping_error_px`` compares. ``period`` Λ and ``wavelength`` in metres.

    Example: 700 nm through a 86.4 µm period, the sensor 50 mm behind the lens on 5.4 µm pixels:
    ``grating_spot_px(Camera(sensor_distance=0.05, sensor_pitch=5.4e-6), 700e-9, 86.4e-6)`` → 75.02 px.
    """
    return camera.sensor_distance * wavelength / period / camera.sensor_pitch


def mapping_error_px(camera: Camera, wavelength: float, period: float) -> float:
    """How far (sensor px) the model's first order (``grating_spot_px``, s·λ/Λ) lies from where a rectilinear lens
    sends it, s·tan(asin(λ/Λ)): s·(tan θ − sin θ) / p, about s·(λ/Λ)³ / (2p).

    Example: ``mapping_error_px(Camera(sensor_distance=0.05, sensor_pitch=5.4e-6), 700e-9, 86.4e-6)`` → 0.0025 px.
    """
    x = wavelength / period
    return camera.sensor_distance * (math.tan(math.asin(x)) - x) / camera.sensor_pitch


def period_for_mapping(camera: Camera, wavelength: float, max_px: float = MAX_MAPPING_PX) -> float:
    """The shortest grating period Λ (m), to 0.01 µm, whose first order of ``wavelength`` (m) the model puts within
    ``max_px`` sensor pixels of where the lens sends it (``mapping_error_px``, which falls as Λ grows).

    Example: the sensor 16 mm behind the lens on 10 µm pixels keeps 700 nm within half a pixel at Λ ≥ 8.21 µm
    (s·(λ/Λ)³/(2p) ≈ 0.5 px): ``period_for_mapping(Camera(sensor_distance=16e-3, sensor_pitch=10e-6), 700e-9)``.
    """
    from scipy.optimize import brentq

    lo, hi = wavelength * (1 + 1e-9), wavelength * 1e6
    exact = float(brentq(lambda period: mapping_error_px(camera, wavelength, period) - max_px, lo, hi,
                         xtol=1e-15, rtol=1e-12))
    um = math.ceil(exact * 1e8) / 100
    while mapping_error_px(camera, wavelength, um * 1e-6) > max_px:
        um = round(um + 0.01, 2)
    return um * 1e-6


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
    ``reach_px`` sensor pixels off axis (``grating_spot_px``): λ·s / (reach · p) rounded up, and up
    again while the rounded period, as a scene writes it in µm, lands beyond the reach; NaN for no reach.

    Example: with the sensor 16 mm behind the lens (``Camera(sensor_distance=16e-3, sensor_pitch=1.55e-6)``),
    700 nm lands within 92 px at Λ ≥ 78.55 µm: ``period_for_reach(cam, 700e-9, 92.0)`` → 7.855e-05.
    """
    if reach_px <= 0:
        return math.nan
    exact = lam_max * camera.sensor_distance / (reach_px * camera.sensor_pitch)
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

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.wavelengths_m is not None:  # the bands given: n_bands is their count, or left at its default
            if self.n_bands not in (len(self.wavelengths_m), type(self).n_bands):
                raise DoefabError(f"GratingTask: n_bands {self.n_bands} disagrees with the {len(self.wavelengths_m)} "
                                  f"wavelengths_m given: give the bands, or their count, not both")
            self.n_bands = len(self.wavelengths_m)

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
        off = mapping_error_px(camera, lam, self.period_m)
        if off > MAX_MAPPING_PX:
            raise DoefabError(
                f"GratingTask: a period of {self.period_m * 1e6:g} µm diffracts {lam * 1e9:g} nm so steeply that the "
                f"PSF model (Fraunhofer, s·λ/Λ) puts its first order {off:.2f} px from where the lens sends it "
                f"(s·tan(asin(λ/Λ))), more than the {MAX_MAPPING_PX:g} px the model holds: set period_m or "
                f"period_pixels (a scene's design.grating_period_um) ≥ "
                f"{period_for_mapping(camera, lam) * 1e6:g} µm")

    PATTERN_HINT = "a longer period_m (a scene's design.grating_period_um)"
    METRIC_WIDTH = ("box_px", "design.grating_box_px")  # the metric's half-width (sensor px): field, scene key

    def first_order_px(self, camera: Camera) -> float:
        """How far off axis (sensor px) the farthest band's first order lands (``grating_spot_px``)."""
        return max(abs(grating_spot_px(camera, lam, self.period(camera))) for lam in self.wavelengths(camera))

    def pattern_reach_px(self, camera: Camera) -> float:
        """The farthest band's first order, its metric box and 2 px (``Task.pattern_reach_px``)."""
        return self.first_order_px(camera) + self.box_px + 2

    def window_px(self, far_px: float) -> int:
        """The least odd PSF window (px) that holds a first order ``far_px`` off axis with its metric box and a 2 px
        margin (``pattern_reach_px``, ``fits_window``): what ``optics.kernel_px`` must reach."""
        return least_window(far_px + self.box_px + 2)

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
