"""The common interface of the pupil-to-sensor propagators, and the sampling checks they share.

A propagator ("route") turns the pupil function of one aperture half into pixel-integrated intensity on
a K × K window of sensor pixels. The pupil function excludes the converging spherical wave of the lens
(the lens images the focus plane perfectly; the paper's Eq. 4 is its paraxial form), so for the Fraunhofer
routes the sensor field is a scaled Fourier transform of it (DESIGN-NOTES erratum on Eq. 4 + 7).

Routes: ``mft`` (matrix Fourier transform straight onto Gauss–Legendre nodes inside each sensor pixel),
``fft`` (zero-padded FFT, then exact integration of the interpolated intensity over each pixel) and
``asm`` (lens phase + band-limited angular spectrum over the lens-to-sensor distance; valid only for
fine pupil sampling, and the right tool for short plane-to-plane gaps, see ``angular_spectrum``).
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch

from doefab.errors import SamplingError

__all__ = ["FocalSetup", "Route", "gauss_legendre_pixel", "check_window", "pixel_integration_matrix",
           "plane_batches", "scratch_kwargs", "BATCH_ELEMENTS"]

#: complex samples (padded transform planes × batch) one batched transform holds at most: a batch of dozens of
#: depth planes on a 1600² grid is GBs, and runs ~1.6× slower than the same planes a few at a time (measured
#: on the committed half-ring design, 65 planes: 40–51 s and 12 GiB against 26 s and 3.6 GiB per part)
BATCH_ELEMENTS = 2**25


@dataclass(frozen=True)
class FocalSetup:
    """Everything a route needs besides the pupil function itself (SI units).

    Attributes:
        x: (Nx,) pupil sample x centres, metres.  y: (Ny,) pupil sample y centres (row 0 = top), metres.
        pitch: pupil sample pitch b, metres.
        envelope: multiply the field by the far field of one b × b sample (flat DOE pixels).
        wavelengths: vacuum wavelengths, metres.
        sensor_distance: lens-to-sensor distance s, metres.
        sensor_pitch: sensor pixel pitch p, metres.
        kernel_size: K, output window is K × K sensor pixels; pixel K // 2 is centred on ``center``.
        center: (u, v) sensor position of pixel (K//2, K//2)'s centre, metres (x right, y up).
        real_dtype: torch.float32 or torch.float64.
        support: (Ny, Nx) bool, the samples that carry light (None: all of them).
    """

    x: np.ndarray
    y: np.ndarray
    pitch: float
    envelope: bool
    wavelengths: tuple[float, ...]
    sensor_distance: float
    sensor_pitch: float
    kernel_size: int
    center: tuple[float, float] = (0.0, 0.0)
    real_dtype: torch.dtype = torch.float32
    support: np.ndarray | None = None  # (Ny, Nx) bool: samples that carry light (None = all)

    @property
    def complex_dtype(self) -> torch.dtype:
        return torch.complex128 if self.real_dtype == torch.float64 else torch.complex64

    def pixel_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(K,) sensor pixel centre coordinates along x (ascending) and y (descending, row 0 = top)."""
        k = np.arange(self.kernel_size) - self.kernel_size // 2
        return k * self.sensor_pitch + self.center[0], -k * self.sensor_pitch + self.center[1]


class Route(Protocol):
    """A pupil-to-sensor propagator."""

    name: str

    def check(self, setup: FocalSetup) -> None:
        """Raise :class:`SamplingError` naming the violated condition and the fix."""

    def prepare(self, setup: FocalSetup) -> object:
        """Precompute what does not depend on the pupil function (matrices, filters)."""

    def intensity(self, pupil: torch.Tensor, index: int, setup: FocalSetup, prepared: object,
                  scratch: dict | None = None) -> torch.Tensor:
        """Pixel-integrated intensity for wavelength ``setup.wavelengths[index]``.

        Args:
            pupil: (..., Ny, Nx) complex pupil function (amplitude = coverage, no lens sphere).
            scratch: a dict the caller keeps over many calls on pupils of the same shape, where a route may keep
                working buffers (the spectral route: its zero-padded FFT canvas); None: none kept.
        Returns:
            (..., K, K) real tensor: energy per sensor pixel, in units of pupil area (m²); divide by
            the clear-aperture area for fractions of the aperture's light.
        """


def gauss_legendre_pixel(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes (as fractions of a pixel, in [-1/2, 1/2]) and weights (summing to 1)."""
    t, w = np.polynomial.legendre.leggauss(int(n))
    return t / 2.0, w / 2.0


def check_window(setup: FocalSetup, route: str) -> None:
    """The sensor window must fit inside the alias-free field of the sampled pupil.

    A pupil sampled at pitch b has a far field that repeats every λ s / b on the sensor; the window
    (half-width (K/2 + 1/2)·p from the chief ray, plus the centre offset) must stay inside ±λ s / (2b)
    for the shortest wavelength.
    """
    lam = min(setup.wavelengths)
    alias_half = lam * setup.sensor_distance / (2 * setup.pitch)
    half = (setup.kernel_size / 2 + 0.5) * setup.sensor_pitch + max(abs(setup.center[0]), abs(setup.center[1]))
    if half > alias_half:
        kmax = int(2 * (alias_half - max(map(abs, setup.center))) / setup.sensor_pitch - 1)
        raise SamplingError(
            f"[{route}] output window aliasing: the K = {setup.kernel_size} px window reaches "
            f"{half * 1e3:.3f} mm from the axis but the pupil sampled at {setup.pitch * 1e6:.3g} µm repeats its "
            f"far field every {2 * alias_half * 1e3:.3f} mm at {lam * 1e9:.0f} nm (alias-free half-width "
            f"{alias_half * 1e3:.3f} mm). Fix: " + (f"a smaller kernel (≤ {kmax} px), " if kmax >= 1 else "")
            + f"a finer pupil sampling (pupil_oversample ≥ {math.ceil(half / alias_half)}) or a finer DOE pitch.")


def check_smooth_phase(phase: np.ndarray, mask: np.ndarray, limit: float, route: str, what: str, q: int) -> None:
    """Neighbouring pupil samples inside ``mask`` may differ in smooth phase by at most ``limit`` radians."""
    worst = 0.0
    for axis in (0, 1):
        d = np.abs(np.diff(phase, axis=axis))
        m = mask[1:, :] & mask[:-1, :] if axis == 0 else mask[:, 1:] & mask[:, :-1]
        if m.any():
            worst = max(worst, float(d[m].max()))
    if worst > limit:
        need = q * math.ceil(worst / limit)
        raise SamplingError(
            f"[{route}] pupil phase sampling: the {what} changes by {worst:.2f} rad between neighbouring pupil "
            f"samples (limit {limit:.2f} rad). Fix: a finer pupil sampling (pupil_oversample ≥ {need}), a "
            f"finer DOE pitch, or a source nearer the plane in focus.")


def pixel_integration_matrix(samples: np.ndarray, spacing: float, edges_lo: np.ndarray,
                             edges_hi: np.ndarray) -> np.ndarray:
    """(K, L) matrix integrating the piecewise-linear interpolant of uniform samples over K intervals.

    Row k holds the exact integral of each sample's hat function over ``[edges_lo[k], edges_hi[k]]``
    (metres), so ``W @ f`` is the pixel integral of the linearly interpolated ``f``.
    """
    d = float(spacing)

    def antideriv(t: np.ndarray) -> np.ndarray:
        t = np.clip(t, -d, d)
        return np.where(t < 0, (t + d) ** 2 / (2 * d), d - (d - t) ** 2 / (2 * d))

    return antideriv(edges_hi[:, None] - samples[None, :]) - antideriv(edges_lo[:, None] - samples[None, :])


def plane_batches(n: int, plane_elements: int) -> list[slice]:
    """Slices cutting a batch of ``n`` planes into runs of at most ``BATCH_ELEMENTS`` samples (at least one plane
    each) for planes of ``plane_elements`` samples."""
    step = max(1, BATCH_ELEMENTS // max(int(plane_elements), 1))
    return [slice(j, min(j + step, n)) for j in range(0, n, step)]


def scratch_kwargs(route) -> dict:
    """``{"scratch": {}}`` for a route whose ``intensity`` takes working buffers kept over many calls
    (``Route.intensity``), else ``{}`` (a route of the user's own with the four-argument signature, or one whose
    signature cannot be read)."""
    try:
        takes = "scratch" in inspect.signature(route.intensity).parameters
    except (TypeError, ValueError):
        takes = False
    return {"scratch": {}} if takes else {}
