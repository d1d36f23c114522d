"""Differentiable Wiener deconvolution (DWDN, Dong et al. 2020), usable on images or feature maps.

``X = conj(K) · Y / (|K|² + λ)`` per channel in the Fourier domain, with ``K`` the optical transfer
function of the PSF (its centre pixel moved to the origin) and ``λ > 0`` a regularisation per channel —
fixed, learned (``WienerDeconvolution``, λ = softplus(θ)) or estimated from the signal-to-noise ratio. Because
λ > 0 the division is bounded by ``|K| / (|K|² + λ) ≤ 1 / (2√λ)``: a PSF with spectral zeros gives a finite
result. The input is padded by edge replication (half a PSF on each side) before the FFT, so the circular
wrap of the FFT does not ring across the image borders, and cropped back afterwards.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from doefab.errors import DoefabError
from doefab.imaging.captures import irfft2_crop

__all__ = ["wiener_deconvolve", "wiener_filter", "psf_to_otf", "WienerDeconvolution"]


def psf_to_otf(psf: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """OTF of [..., K, K] PSFs on an (H, W) grid: zero-padded, centre pixel (K//2, K//2) rolled to (0, 0)."""
    k_h, k_w = psf.shape[-2:]
    h, w = shape
    if k_h > h or k_w > w:
        raise DoefabError(f"PSF {k_h}×{k_w} is larger than the padded image {h}×{w}: crop the PSF")
    pad = F.pad(psf, (0, w - k_w, 0, h - k_h))
    pad = torch.roll(pad, shifts=(-(k_h // 2), -(k_w // 2)), dims=(-2, -1))
    return torch.fft.rfft2(pad)


def wiener_filter(psf: torch.Tensor, lam, shape: tuple[int, int], images: int = 1, each: bool = False,
                  dtype: torch.dtype = torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """(OTF, |OTF|² + λ): the Wiener filter of ``psf`` for [B, ``images``, H, W] inputs of (H, W) ``shape``, on
    :func:`wiener_deconvolve`'s padded grid (arguments as there). It depends on the PSF and λ only, so a caller
    that deconvolves many images with one PSF computes it once (``CodedFeatures`` at inference).

    ``shape`` in pixels; λ relative to the unit-sum PSF's OTF (1 at zero frequency).

    Example: ``otf, den = wiener_filter(psf[None], 1e-2, (64, 64), images=3)`` with ``psf`` [3, 15, 15]."""
    if psf.ndim != 4:
        raise DoefabError(f"the PSF must be [B, C, K, K], got {tuple(psf.shape)}")
    lam = torch.as_tensor(lam, dtype=dtype, device=psf.device)
    if bool((lam <= 0).any()) or not bool(torch.isfinite(lam).all()):
        raise DoefabError("the Wiener regularisation λ must be positive and finite")
    k_h, k_w = psf.shape[-2:]
    h, w = shape[0] + 2 * (k_h // 2 + 1), shape[1] + 2 * (k_w // 2 + 1)
    p = psf.to(dtype)
    p = p / p.sum(dim=(-2, -1), keepdim=True).clamp_min(1e-12)
    otf = psf_to_otf(p, (h, w))
    if each:  # [B, C, 1, h, w']: PSF c for every image f
        otf = otf[:, :, None]
    if lam.ndim == 1:
        lam = lam.reshape((1, psf.shape[1], images, 1, 1) if each else (1, -1, 1, 1))
    return otf, otf.abs() ** 2 + lam


def wiener_deconvolve(y: torch.Tensor, psf: torch.Tensor, lam, each: bool = False,
                      filt: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
    """Wiener-deconvolve [B, C, H, W] ``y`` with [B or 1, C or 1, K, K] ``psf``; ``lam`` > 0 scalar or [C].

    The PSF is normalised to unit sum per channel (so the result keeps the image's scale whatever fraction of
    the light the PSF carries). ``each``: every one of ``y``'s F channels with every one of the C PSFs, output
    channel ``c·F + f`` (``lam`` scalar or [C·F]) — the same numbers as ``y.repeat(1, C, 1, 1)`` deconvolved with
    ``psf.repeat_interleave(F, dim=1)``, with F transforms of the image instead of C·F. ``filt``: the filter
    :func:`wiener_filter` gives for these arguments, if already computed (then only ``psf``'s size is read).

    Example: ``wiener_deconvolve(torch.rand(1, 3, 64, 64), psf[None], 1e-2)`` with ``psf`` [3, 15, 15].
    """
    if y.ndim != 4 or psf.ndim != 4:
        raise DoefabError(f"wiener_deconvolve takes y [B, C, H, W] and psf [B, C, K, K], got {tuple(y.shape)} and "
                          f"{tuple(psf.shape)}")
    otf, den = filt if filt is not None else wiener_filter(psf, lam, y.shape[-2:], y.shape[1], each, y.dtype)
    k_h, k_w = psf.shape[-2:]
    ph, pw = k_h // 2 + 1, k_w // 2 + 1
    yp = F.pad(y, (pw, pw, ph, ph), mode="replicate")
    h, w = yp.shape[-2:]
    spec = torch.fft.rfft2(yp)
    if each:  # [B, C, F, h, w']: PSF c on image f, flattened to channel c·F + f
        spec = spec[:, None]
    q = torch.conj(otf) * spec
    # in place where λ does not widen the product (one large temporary fewer); the frame cropped between the
    # inverse transform's passes
    q = q.div_(den) if torch.broadcast_shapes(q.shape, den.shape) == q.shape else q / den
    x = irfft2_crop(q, (h, w), slice(ph, ph + y.shape[-2]), slice(pw, pw + y.shape[-1]))
    return x.flatten(1, 2) if each else x


class WienerDeconvolution(torch.nn.Module):
    """Wiener layer with a learned λ per channel (λ = softplus(θ) + 1e-6, initialised at ``lam0``)."""

    def __init__(self, channels: int, lam0: float = 1e-2):
        super().__init__()
        if lam0 <= 0:
            raise DoefabError("lam0 must be > 0")
        init = torch.log(torch.expm1(torch.tensor(float(lam0))))
        self.theta = torch.nn.Parameter(init.repeat(channels))

    @property
    def lam(self) -> torch.Tensor:
        return F.softplus(self.theta) + 1e-6

    def forward(self, y: torch.Tensor, psf: torch.Tensor, each: bool = False) -> torch.Tensor:
        return wiener_deconvolve(y, psf, self.lam, each)
