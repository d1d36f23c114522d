"""How well a design's coded PSFs encode depth, without a network: discriminability of neighbouring depth planes.

A textured patch at depth z_i is seen through PSF P_i; telling it from the same patch at the neighbouring plane
z_{i+1} is a detection problem whose signal is the difference image (P_i − P_{i+1}) * x. For a texture x with
power spectrum S(f) (natural images: S ∝ 1/(|f|² + f0²), normalised to the texture's variance c²) its expected
energy per pixel is

    E_i = c² · Σ_λ Σ_f S(f) |OTF_i,λ(f) − OTF_{i+1},λ(f)|²,

and under the sensor's noise (variance σ² per pixel at the mean signal) a patch of M pixels gives the
discriminability d'_i = sqrt(M · E_i / σ²). An ideal observer confuses the two planes with probability
Q(d'_i / 2); the **predicted confusion error** sums, over the planes, the depth step times that probability
(metres, lower is better) — the network-free counterpart of the depth network's MAE. ``min_dprime`` is the
single worst pair. Cost: two FFTs per PSF, milliseconds for a depth stack, cheap enough inside design and
tolerance loops.

Noise defaults are the capture simulation's ("default": 25 000 e⁻ full well, 3 e⁻ read noise; see
``doefab.imaging.sensor``) at a mean signal of 25 % of full scale, texture contrast c = 0.05 and 8 × 8-pixel
patches (a depth map resolves about that much). They set the absolute scale of d', not the order of two
designs by d'; they were chosen so that d' of the committed designs lies around 1–10, where the confusion
probability is informative (with 32-pixel patches at c = 0.1 every plane pair is told apart, d' > 12, and the
predicted error is 0 for every design).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from doefab.validate import depths as _validate_depths
from doefab.validate import number_in
from doefab.errors import DoefabError
from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E

__all__ = ["depth_encoding_score", "texture_spectrum"]


def texture_spectrum(n: int, patch: int = 32, kind: str = "natural") -> np.ndarray:
    """(n, n) power spectrum over FFT frequencies (cycles/pixel), normalised to sum 1 (unit-variance texture)."""
    f = np.fft.fftfreq(n)
    f2 = f[None, :] ** 2 + f[:, None] ** 2
    if kind == "white":
        s = np.ones((n, n))
    elif kind == "natural":
        s = 1.0 / (f2 + (1.0 / patch) ** 2)
    else:
        raise DoefabError(f"unknown texture spectrum {kind!r}: natural or white")
    s[0, 0] = 0.0  # a uniform patch tells nothing about blur
    return s / s.sum()


def depth_encoding_score(psf, depths, signal: float = 0.25, contrast: float = 0.05, patch: int = 8,
                         full_well: float = DEFAULT_FULL_WELL_E, read_noise: float = DEFAULT_READ_NOISE_E,
                         spectrum: str = "natural") -> dict:
    """Depth discriminability of a PSF stack.

    Args:
        psf: (D, W, K, K) coded PSFs (energy fractions) for D depth planes, W wavelengths (torch or numpy).
        depths: the D planes' depths in metres (sorted or not).
        signal: mean signal, fraction of full scale.  contrast: texture standard deviation, same unit.
        patch: patch side in pixels (M = patch²).  full_well, read_noise: electrons.
        spectrum: ``"natural"`` (1/f²) or ``"white"`` texture.
    Returns:
        {"predicted_error_m", "min_dprime", "mean_log10_dprime", "dprime": [...], "pairs_m": [[z_i, z_i+1], ...]}

    Example:

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)  # focused at 5 m
        >>> pair = doefab.split_aperture_psf(None, cam, [550e-9], [2.0, 3.0, 5.0], kernel_size=31)
        >>> score = doefab.depth_encoding_score(pair.uncoded, [2.0, 3.0, 5.0])
        >>> score["pairs_m"], score["min_dprime"] > 1  # neighbouring planes told apart
        ([[2.0, 3.0], [3.0, 5.0]], True)
    """
    for name, v, lo, hi in (("signal", signal, 0, 1), ("contrast", contrast, 0, 1)):
        number_in(name, v, lo, hi, unit="(a fraction of full scale, not a percentage)", lo_open=True)
    patch = number_in("patch", patch, 1, 4096, integer=True, unit="pixels")
    number_in("full_well", full_well, 0, 1e7, unit="electrons", lo_open=True)
    number_in("read_noise", read_noise, 0, 1e4, unit="electrons")
    p = torch.as_tensor(psf).detach().to(torch.float64)
    if p.ndim != 4:
        raise DoefabError(f"psf must be (depths, wavelengths, K, K), got shape {tuple(p.shape)}")
    if not bool(torch.isfinite(p).all()) or bool((p < 0).any()):
        raise DoefabError("psf must hold finite, non-negative energy fractions")
    z = np.asarray(_validate_depths(depths), dtype=float)
    if len(z) != p.shape[0] or len(z) < 2:
        raise DoefabError(f"need one PSF per depth and at least 2 depths: {p.shape[0]} PSFs, {len(z)} depths")
    order = np.argsort(z)
    z, p = z[order], p[torch.from_numpy(order.copy())]
    k = p.shape[-1]
    n = 2 * k  # zero-padded: linear, not circular, blur
    otf = torch.fft.fft2(p, s=(n, n))
    s = torch.from_numpy(texture_spectrum(n, patch, spectrum))
    electrons = signal * full_well
    sigma = math.sqrt(electrons + read_noise**2) / full_well  # per pixel, fraction of full scale
    dprime = []
    for i in range(len(z) - 1):
        diff = (otf[i] - otf[i + 1]).abs() ** 2  # (W, n, n)
        energy = contrast**2 * float((diff * s).sum()) / p.shape[1]  # mean over wavelengths (colour channels)
        dprime.append(math.sqrt(patch * patch * energy) / sigma)
    dprime = np.array(dprime)
    confusion = 0.5 * np.array([math.erfc(d / 2 / math.sqrt(2)) for d in dprime])  # Q(d'/2)
    err = float(np.sum(np.diff(z) * confusion) / len(z))
    return {"predicted_error_m": err, "min_dprime": float(dprime.min()),
            "mean_log10_dprime": float(np.mean(np.log10(np.maximum(dprime, 1e-12)))),
            "dprime": [float(v) for v in dprime], "pairs_m": [[float(a), float(b)] for a, b in zip(z[:-1], z[1:])]}
