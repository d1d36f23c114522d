"""Cross-blur consistency: a depth cost volume from the two captures of a split aperture (classic two-image
depth from defocus, made possible here because both halves see the same scene at once).

For a fronto-parallel patch of radiance ``s`` at depth ``z`` the captures are ``c = p_c(z) ∗ s`` and
``u = p_u(z) ∗ s``, so ``p_u(z) ∗ c − p_c(z) ∗ u = 0`` exactly (convolution commutes), whatever the scene's
texture. At a wrong plane ``z'`` the residual does not vanish where the scene has texture. The locally
averaged residual energy over the PSF pair's depth planes is a cost volume whose minimum marks the depth; a
textureless patch gives a flat cost (no information), which the network fills in from context.

``cross_blur_cost`` works on batches, is differentiable in the captures and the PSFs (end-to-end design), and
pads by edge replication so image borders do not read as structure.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from doefab.errors import DoefabError
from doefab.imaging.captures import irfft2_crop

__all__ = ["cross_blur_cost", "relative_log_cost"]


def cross_blur_cost(coded: torch.Tensor, uncoded: torch.Tensor, psf_coded: torch.Tensor, psf_uncoded: torch.Tensor,
                    window: int = 9) -> torch.Tensor:
    """[B, D, H, W] mean residual energy ``|p_u(z)∗c − p_c(z)∗u|²`` (summed over colour, averaged over a
    ``window``-pixel square) for each of the D depth planes.

    Args:
        coded, uncoded: [B, 3, H, W] captures.  psf_coded, psf_uncoded: [D, 3, K, K] PSFs of the planes.
    """
    if coded.shape != uncoded.shape or coded.ndim != 4:
        raise DoefabError(f"captures must be two [B, 3, H, W] tensors of one shape, got {tuple(coded.shape)} and "
                          f"{tuple(uncoded.shape)}")
    if psf_coded.shape != psf_uncoded.shape or psf_coded.ndim != 4 or psf_coded.shape[1] != coded.shape[1]:
        raise DoefabError(f"PSFs must be two [D, {coded.shape[1]}, K, K] tensors of one shape, got "
                          f"{tuple(psf_coded.shape)} and {tuple(psf_uncoded.shape)}")
    if window < 1 or window % 2 == 0:
        raise DoefabError(f"window must be an odd number of pixels, got {window}")
    k = psf_coded.shape[-1]
    h, w = coded.shape[-2:]
    pad = k // 2
    fh, fw = h + 2 * pad + k - 1, w + 2 * pad + k - 1
    pc = psf_coded.to(coded.dtype)
    pu = psf_uncoded.to(coded.dtype)
    spec_c = torch.fft.rfft2(F.pad(coded, (pad, pad, pad, pad), mode="replicate"), s=(fh, fw))[:, None]
    spec_u = torch.fft.rfft2(F.pad(uncoded, (pad, pad, pad, pad), mode="replicate"), s=(fh, fw))[:, None]
    otf_c = torch.fft.rfft2(pc, s=(fh, fw))[None]
    otf_u = torch.fft.rfft2(pu, s=(fh, fw))[None]
    # one inverse FFT per plane: the residual is linear, so it is formed in the Fourier domain
    c0 = pad + k // 2
    res = irfft2_crop(otf_u * spec_c - otf_c * spec_u, (fh, fw), slice(c0, c0 + h), slice(c0, c0 + w))  # [B,D,3,H,W]
    energy = (res**2).sum(dim=2)  # [B, D, H, W]
    return F.avg_pool2d(energy, window, 1, window // 2, count_include_pad=False)


def relative_log_cost(cost: torch.Tensor, eps: float = 1e-7) -> torch.Tensor:
    """Network input from a cost volume: ``log(cost + eps)`` minus its mean over the planes, so it does not depend
    on the scene's contrast (a flat profile means no depth information at that pixel)."""
    lc = torch.log(cost + eps)
    return lc - lc.mean(dim=1, keepdim=True)
