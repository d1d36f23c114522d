"""The authors' published route, kept as a benchmark baseline (not for production use).

The paper's Eq. 1–7 as published code does it: the quadratic lens phase (Eq. 4) and the source's spherical phase
(Eq. 1) sampled on the DOE grid, the grid zero-padded by R/2 on each side, a Fresnel transfer-function
convolution over the lens-to-sensor distance, and average pooling to the sensor pitch. At 5.4 µm the
lens phase changes by several radians per DOE pixel at the aperture edge, so this route aliases
(DESIGN-NOTES erratum); it runs without sampling checks on purpose.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from doefab.optics.camera import Camera

__all__ = ["authors_fresnel_psf"]


def authors_fresnel_psf(height: np.ndarray, camera: Camera, wavelengths, depth: float, kernel_size: int,
                        half: str = "coded", pad: int | None = None) -> np.ndarray:
    """Coded (or uncoded) PSF by the authors' route.

    Args:
        height: (N, N) heights, metres.  wavelengths: metres.  depth: metres or inf.
        kernel_size: K sensor pixels.  pad: zero padding per side in DOE pixels (default R/2, R = N/2).
    Returns:
        (n_wavelengths, K, K) float64 energy fractions of the whole aperture's light.
    """
    n, a = camera.doe_pixels, camera.doe_pitch
    pad = n // 4 if pad is None else int(pad)
    m = n + 2 * pad
    pool = max(1, int(round(camera.sensor_pitch / a)))
    c = (np.arange(n) - n / 2) * a
    xx, yy = np.meshgrid(c, -c)
    r2 = xx**2 + yy**2
    inside = r2 < (camera.aperture_diameter / 2) ** 2
    amp = inside & ((xx < 0) if half == "coded" else (xx >= 0))
    f = camera.focal_length
    freq = np.fft.fftfreq(m, d=a)
    fx, fy = np.meshgrid(freq, freq)
    out = []
    for lam in wavelengths:
        k = 2 * math.pi / lam
        dn = float(camera.material.index(lam)) - 1.0
        src = 0.0 if math.isinf(depth) else k * np.sqrt(r2 + depth**2)
        phase = src + k * dn * height - k * r2 / (2 * f)
        u0 = np.zeros((m, m), np.complex64)
        u0[pad:pad + n, pad:pad + n] = amp * np.exp(1j * phase)
        h = np.exp(-1j * math.pi * lam * camera.sensor_distance * (fx**2 + fy**2))
        u1 = torch.fft.ifft2(torch.fft.fft2(torch.from_numpy(u0)) * torch.from_numpy(h.astype(np.complex64)))
        inten = (u1.real**2 + u1.imag**2).numpy().astype(np.float64)
        span = kernel_size * pool
        start = m // 2 - (kernel_size // 2) * pool - pool // 2
        crop = inten[start:start + span, start:start + span]
        pooled = crop.reshape(kernel_size, pool, kernel_size, pool).sum(axis=(1, 3))
        out.append(pooled / (2 * amp.sum()))
    return np.stack(out)
