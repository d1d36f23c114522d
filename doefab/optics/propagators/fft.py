"""Zero-padded FFT route (the usual approach in published code), done carefully.

The pupil is zero-padded to L × L so that the FFT samples the sensor field every δ = λ s / (L b) ≤ p / ovs;
the intensity is then integrated over each sensor pixel exactly for its piecewise-linear interpolant
(no nearest-neighbour resampling, no average pooling across misaligned grids).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft
import torch

from doefab.validate import number_in
from doefab.errors import SamplingError
from doefab.optics.propagators.base import FocalSetup, check_window, pixel_integration_matrix

__all__ = ["FFTRoute"]


class FFTRoute:
    """Zero-padded FFT, then exact integration of the linearly interpolated intensity over pixels.

    Args:
        oversample: FFT samples per sensor pixel pitch (δ ≤ p / oversample) at every wavelength.
        max_size: largest padded FFT size L accepted (memory guard).
    """

    name = "fft"

    def __init__(self, oversample: float = 4.0, max_size: int = 16384):
        self.oversample = number_in("oversample", oversample, 0, 256, lo_open=True)  # FFT samples per sensor pixel
        self.max_size = int(max_size)

    def _size(self, setup: FocalSetup, lam: float) -> int:
        need = self.oversample * lam * setup.sensor_distance / (setup.pitch * setup.sensor_pitch)
        return scipy.fft.next_fast_len(int(math.ceil(max(need, len(setup.x), len(setup.y)))))

    def check(self, setup: FocalSetup) -> None:
        check_window(setup, self.name)
        big = max(self._size(setup, lam) for lam in setup.wavelengths)
        if big > self.max_size:
            raise SamplingError(
                f"[fft] padding: reaching {self.oversample:g} samples per sensor pixel needs an FFT of "
                f"{big} × {big} (limit {self.max_size}). Fix: use the mft route, lower the oversampling, or "
                f"raise max_size if memory allows.")

    def prepare(self, setup: FocalSetup):
        uc, vc = setup.pixel_centres()
        p = setup.sensor_pitch
        half = (setup.kernel_size / 2 + 1) * p
        out = []
        for lam in setup.wavelengths:
            n = self._size(setup, lam)
            delta = lam * setup.sensor_distance / (n * setup.pitch)
            m = np.arange(-(n // 2), n - n // 2)
            keep_u = np.abs(m * delta - setup.center[0]) <= half + delta
            keep_v = np.abs(m * delta - setup.center[1]) <= half + delta
            iu, iv = np.mod(m[keep_u], n), np.mod(m[keep_v], n)
            su, sv = m[keep_u] * delta, m[keep_v] * delta
            wx = pixel_integration_matrix(su, delta, uc - p / 2, uc + p / 2)
            wy = pixel_integration_matrix(sv, delta, vc - p / 2, vc + p / 2)
            if setup.envelope:
                scale = setup.pitch / (lam * setup.sensor_distance)
                wx = wx * np.sinc(su * scale)[None, :] ** 2
                wy = wy * np.sinc(sv * scale)[None, :] ** 2
            rd = setup.real_dtype
            out.append((n, torch.from_numpy(iv), torch.from_numpy(iu), torch.from_numpy(wy).to(rd),
                        torch.from_numpy(wx.T.copy()).to(rd)))
        return out

    def intensity(self, pupil: torch.Tensor, index: int, setup: FocalSetup, prepared,
                  scratch: dict | None = None) -> torch.Tensor:
        n, iv, iu, wy, wxt = prepared[index]
        lam = setup.wavelengths[index]
        scale = setup.pitch**2 / (lam * setup.sensor_distance)
        # rows are stored top (largest y) first; flip so that FFT index m maps to +m·δ along y too
        field = torch.fft.fft2(torch.flip(pupil, dims=(-2,)), s=(n, n))
        field = field.index_select(-2, iv).index_select(-1, iu)
        inten = (field.real**2 + field.imag**2) * scale**2
        return wy @ inten @ wxt
