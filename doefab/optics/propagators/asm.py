"""Band-limited angular spectrum (Matsushima & Shimobaba 2009): plane-to-plane propagation on one grid.

``angular_spectrum`` propagates a sampled field over a distance z (the DOE-to-aperture gap, or any short
distance); ``ASMRoute`` uses it for the whole lens-to-sensor distance after applying the lens's converging
sphere, which is the paper's literal route (Eq. 4–7) and is valid only where the pupil sampling resolves
that sphere: it refuses the default camera and says why.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft
import torch

from doefab.validate import length_m, number_in, wavelength_m
from doefab.errors import DoefabError, SamplingError
from doefab.optics.propagators.base import FocalSetup, check_smooth_phase, pixel_integration_matrix

__all__ = ["angular_spectrum", "asm_band_limit", "ASMRoute"]


def asm_band_limit(n: int, pitch: float, wavelength: float, distance: float) -> float:
    """Matsushima's band limit (cycles/m) for an L = n grid: 1 / (λ sqrt((2 Δf z)² + 1)), Δf = 1/(n b)."""
    df = 1.0 / (n * pitch)
    return 1.0 / (wavelength * math.sqrt((2.0 * df * distance) ** 2 + 1.0))


def angular_spectrum(field: torch.Tensor, pitch: float, wavelength: float, distance: float, pad: int = 2,
                     check: bool = True, max_cut: float = 1e-3) -> torch.Tensor:
    """Propagate a sampled complex field over ``distance`` with the band-limited angular spectrum.

    Args:
        field: (..., Ny, Nx) field on a grid of pitch ``pitch`` (metres): a tensor or array, complex or real (an
            amplitude; propagated as the complex field it is).
        wavelength: metres.  distance: metres (may be negative to propagate backwards).
        pad: the grid is zero-padded to ``pad`` times its size (linear, not circular, convolution).
        check: refuse when more than ``max_cut`` of the field's energy lies beyond the band limit or
            the evanescent cut-off (the result would silently lose it).
    Returns:
        (..., Ny, Nx) complex field at the new plane, same grid.

    Example:

        >>> import numpy as np, doefab
        >>> out = doefab.angular_spectrum(np.ones((64, 64)), 10e-6, 550e-9, 1e-3)  # 10 µm grid, 550 nm, 1 mm on
        >>> tuple(out.shape), round(abs(complex(out[32, 32])), 2)  # a plane wave's centre keeps its amplitude
        ((64, 64), 1.0)
    """
    pitch = length_m("pitch", pitch, 1e-8, 1e-2)
    wavelength = wavelength_m("wavelength", wavelength)
    distance = number_in("distance", distance, -1e3, 1e3, unit="m")
    pad = number_in("pad", pad, 1, 64)  # a padding factor (the grid grows to pad × its size)
    field = field if isinstance(field, torch.Tensor) else torch.as_tensor(np.asarray(field))
    if field.dtype in (torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64):
        field = field.to(torch.float64)  # an integer amplitude mask
    if field.ndim < 2 or not (field.is_complex() or field.is_floating_point()):
        raise DoefabError(f"angular_spectrum: field must be a (..., Ny, Nx) complex or real array of numbers, got "
                          f"shape {tuple(field.shape)} of {field.dtype}")
    ny, nx = field.shape[-2:]
    n = scipy.fft.next_fast_len(int(pad * max(ny, nx)))
    spec = torch.fft.fft2(field, s=(n, n))
    f = np.fft.fftfreq(n, d=pitch)
    fy, fx = np.meshgrid(f, f, indexing="ij")
    lim = asm_band_limit(n, pitch, wavelength, abs(distance))
    arg = 1.0 / wavelength**2 - fx**2 - fy**2
    keep = (np.abs(fx) < lim) & (np.abs(fy) < lim) & (arg > 0)
    if check:
        power = (spec.real**2 + spec.imag**2).detach()
        power = power.reshape(-1, n, n).sum(0).cpu().numpy()
        cut = float(power[~keep].sum()) / max(float(power.sum()), 1e-300)
        if cut > max_cut:
            raise SamplingError(
                f"[asm] transfer-function aliasing: {cut:.2%} of the field's energy lies beyond the band limit "
                f"{lim:.4g} cycles/m for z = {distance:g} m on this grid (limit {max_cut:.1%}). Fix: a larger "
                f"padding (pad > {pad}), a shorter distance, or a Fourier-transform route for long distances.")
    h = np.where(keep, np.exp(2j * np.pi * distance * np.sqrt(np.maximum(arg, 0.0))), 0.0)
    h = torch.from_numpy(h).to(spec.device, spec.dtype)  # complex even where the field given was real
    out = torch.fft.ifft2(spec * h)
    return out[..., :ny, :nx]


class ASMRoute:
    """Lens sphere + band-limited angular spectrum over s, then pixel integration (the paper's Eq. 4–7 made exact).

    Args:
        pad: zero-padding factor of the angular spectrum grid (the output window must fit inside it).
    """

    name = "asm"

    def __init__(self, pad: int = 2):
        self.pad = int(pad)

    def _lens_phase(self, setup: FocalSetup, lam: float) -> np.ndarray:
        r2 = setup.y[:, None] ** 2 + setup.x[None, :] ** 2
        s = setup.sensor_distance
        return -2 * np.pi / lam * r2 / (np.sqrt(r2 + s * s) + s)

    def check(self, setup: FocalSetup) -> None:
        lam = min(setup.wavelengths)
        phase = self._lens_phase(setup, lam)
        support = setup.support if setup.support is not None else np.ones(phase.shape, bool)
        check_smooth_phase(phase, support, math.pi, self.name, "lens's converging wave", 1)
        n, i0, j0 = self._placement(setup)
        span = n * setup.pitch / 2
        half = (setup.kernel_size / 2 + 0.5) * setup.sensor_pitch
        if half > span or min(i0, j0) < 0 or i0 + len(setup.y) > n or j0 + len(setup.x) > n:
            raise SamplingError(
                f"[asm] output window: the K = {setup.kernel_size} px window ({2 * half * 1e3:.3f} mm) does not fit "
                f"the {n}-sample computation grid ({2 * span * 1e3:.3f} mm) together with the pupil. Fix: raise pad, "
                f"use a smaller kernel or a window closer to the axis.")

    def _placement(self, setup: FocalSetup) -> tuple[int, int, int]:
        """Padded size n and the (row, column) offset that centres the n × n grid on the sensor window."""
        n = scipy.fft.next_fast_len(int(self.pad * max(len(setup.x), len(setup.y))))
        j0 = int(round((setup.x[0] - (setup.center[0] - (n // 2) * setup.pitch)) / setup.pitch))
        i0 = int(round(((setup.center[1] + (n // 2) * setup.pitch) - setup.y[0]) / setup.pitch))
        return n, i0, j0

    def prepare(self, setup: FocalSetup):
        uc, vc = setup.pixel_centres()
        p = setup.sensor_pitch
        n, i0, j0 = self._placement(setup)
        gx = setup.x[0] + (np.arange(n) - j0) * setup.pitch
        gy = setup.y[0] - (np.arange(n) - i0) * setup.pitch
        wx = pixel_integration_matrix(gx, setup.pitch, uc - p / 2, uc + p / 2)
        wy = pixel_integration_matrix(gy, setup.pitch, vc - p / 2, vc + p / 2)
        lenses = [torch.from_numpy(np.exp(1j * self._lens_phase(setup, lam))).to(setup.complex_dtype)
                  for lam in setup.wavelengths]
        rd = setup.real_dtype
        return lenses, torch.from_numpy(wy).to(rd), torch.from_numpy(wx.T.copy()).to(rd), (n, i0, j0)

    def intensity(self, pupil: torch.Tensor, index: int, setup: FocalSetup, prepared,
                  scratch: dict | None = None) -> torch.Tensor:
        lenses, wy, wxt, (n, i0, j0) = prepared
        lam = setup.wavelengths[index]
        field = pupil * lenses[index]
        ny, nx = field.shape[-2:]
        big = torch.zeros(*field.shape[:-2], n, n, dtype=field.dtype, device=field.device)
        big[..., i0:i0 + ny, j0:j0 + nx] = field
        out = angular_spectrum(big, setup.pitch, lam, setup.sensor_distance, pad=1, check=False)
        inten = out.real**2 + out.imag**2
        return wy @ inten @ wxt
