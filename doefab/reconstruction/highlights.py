"""The scene radiance from the captures by least squares: clipped highlights recovered from the streak.

Where the uncoded (plain) capture clips, its pixels say only "brighter than full well". The coded half spreads
each highlight along the streak into many pixels that stay below clipping, each a scaled copy of the
highlight, so with the coded capture the highlight radiance is the solution of a linear problem:

- start ``x0``: the reference capture divided by its half's light fraction (its PSF sum), and the clipping
  level ``1 / fraction`` where it clips (any channel, grown by one pixel); the reference is the uncoded capture
  when the solve may use it, the coded one otherwise;
- unknowns: every pixel of the frame and of a margin of half a PSF window around it (the light that enters the
  frame from outside; edge-replicated at the start);
- ``x`` minimises ``Σ_v ‖M_v (p_v ∗ x − y_v)‖²`` over the views ``v`` the solve may use, where ``M_v`` keeps
  only the view's unclipped pixels: conjugate gradients on the normal equations (CGLS) from ``x0`` with Jacobi
  preconditioning (each unknown scaled by its column norm; unknowns whose light reaches no unclipped pixel stay
  at the start), stopped after ``iters`` iterations or when the residual reaches rounding level.

Measured on 12 held-out HDR test scenes of 256² (``benchmarks/hdr_solve.py``): highlight PSNR (peak 2^8) 25.2 dB
at the start, 29.1 dB after 20 iterations and 30.0 after 40 from both captures, 28.6 after 40 from the coded
capture alone, and 24.1 from the uncoded capture alone (its clipped interior is seen only through the plain
PSF's faint glow).
The HDR networks take the solve from the captures their variant sees as their input and the baseline their
output refines (``DeconvNet(highlight_iters=N)``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from doefab.errors import DoefabError
from doefab.reconstruction.wiener import psf_to_otf

__all__ = ["solve_highlights", "highlight_support", "VIEWS"]


VIEWS = ("coded", "uncoded")


def highlight_support(capture: torch.Tensor, clipped: float = 0.98, grow_px: int = 1) -> torch.Tensor:
    """[B, 1, H, W] 1 where ``capture`` clips in any channel, grown by ``grow_px`` pixels."""
    s = (capture >= clipped).any(dim=1, keepdim=True).to(capture.dtype)
    return F.max_pool2d(s, 2 * grow_px + 1, 1, grow_px) if grow_px else s


def solve_highlights(coded: torch.Tensor, uncoded: torch.Tensor, psf_coded: torch.Tensor,
                     psf_uncoded: torch.Tensor, iters: int = 40, views: tuple[str, ...] = VIEWS,
                     clipped: float = 0.98, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """[B, 3, H, W] least-squares radiance in [0, 2^8] (module docstring).

    Args:
        coded, uncoded: [B, 3, H, W] captures in [0, 1].  psf_coded, psf_uncoded: [3, K, K] RGB PSFs (each
            carrying its half's share of the light, as simulated).  iters: CGLS iterations (0: the clipping
            level).  views: the captures the solve may use — both (the proposed network), or one of them (the
            ablations).  dtype: of the iterations (float64 for convergence studies).
    """
    if coded.ndim != 4 or coded.shape != uncoded.shape or coded.shape[1] != 3:
        raise DoefabError(f"captures must be two [B, 3, H, W] tensors, got {tuple(coded.shape)}, {tuple(uncoded.shape)}")
    if psf_coded.shape != psf_uncoded.shape or psf_coded.ndim != 3 or psf_coded.shape[0] != 3:
        raise DoefabError(f"PSFs must be two [3, K, K] tensors, got {tuple(psf_coded.shape)}, {tuple(psf_uncoded.shape)}")
    if iters < 0:
        raise DoefabError(f"iters must be ≥ 0, got {iters}")
    if not views or any(v not in VIEWS for v in views):
        raise DoefabError(f"views must be a non-empty subset of {VIEWS}, got {views!r}")
    with torch.no_grad():
        h, w = coded.shape[-2:]
        m = psf_coded.shape[-1] // 2
        big = (h + 2 * m, w + 2 * m)
        caps = {"coded": coded.to(dtype), "uncoded": uncoded.to(dtype)}
        psfs = {"coded": psf_coded.to(dtype), "uncoded": psf_uncoded.to(dtype)}
        ref = "uncoded" if "uncoded" in views else "coded"
        otf = {k: psf_to_otf(psfs[k], big) for k in views}
        share = psfs[ref].sum(dim=(-2, -1)).clamp_min(1e-6).view(1, 3, 1, 1)
        support = highlight_support(caps[ref], clipped)
        x0 = torch.where(support > 0, (1.0 / share).expand_as(caps[ref]), caps[ref] / share)  # start at clipping
        # the scene beyond the frame: edge-replicated (light from just outside enters the frame)
        x0 = F.pad(x0, (m, m, m, m), mode="replicate")
        keep = {k: F.pad((caps[k] < clipped).to(dtype), (m, m, m, m)) for k in views}
        ys = {k: F.pad(caps[k], (m, m, m, m)) * keep[k] for k in views}

        # Jacobi preconditioning: each unknown scaled by 1 / its column norm ‖A e_j‖ (the light of pixel j that
        # lands on unclipped pixels of the views) — pixels deep inside a large clipped blob reach few of them
        # and would otherwise converge last.
        norm2 = sum(torch.fft.irfft2(torch.fft.rfft2(keep[k]) * psf_to_otf(torch.flip(psfs[k] ** 2, (-2, -1)), big),
                                     s=big) for k in views)
        # unknowns whose light reaches (almost) no unclipped pixel stay at the start: nothing measures them
        seen = norm2 > 1e-6 * norm2.amax(dim=(-2, -1), keepdim=True)
        scale = seen / norm2.clamp_min(1e-30).sqrt()

        def fwd(z):
            fx = torch.fft.rfft2(z * scale)
            return {k: torch.fft.irfft2(fx * otf[k], s=big) * keep[k] for k in views}

        def adj(r):
            acc = sum(torch.fft.rfft2(r[k]) * otf[k].conj() for k in views)  # r is zero where a view clips
            return torch.fft.irfft2(acc, s=big) * scale

        def dot(a, c):
            return (a * c).sum(dim=(1, 2, 3), keepdim=True)

        z = torch.zeros_like(x0)
        fx0 = torch.fft.rfft2(x0)
        r = {k: ys[k] - torch.fft.irfft2(fx0 * otf[k], s=big) * keep[k] for k in views}
        s = adj(r)
        p, gamma = s, dot(s, s)
        # an image whose normal-equation residual has fallen to rounding level stops (CGLS breaks down there)
        floor = gamma * (100.0 * torch.finfo(dtype).eps) ** 2
        for _ in range(iters):
            q = fwd(p)
            alpha = torch.where(gamma > floor, gamma / sum(dot(q[k], q[k]) for k in views).clamp_min(1e-30), 0.0)
            z = z + alpha * p
            r = {k: r[k] - alpha * q[k] for k in views}
            s = adj(r)
            g_new = dot(s, s)
            p, gamma = s + g_new / gamma.clamp_min(1e-30) * p, g_new
        x = x0 + z * scale
        return x[..., m:m + h, m:m + w].clamp(0.0, 256.0).to(coded.dtype)
