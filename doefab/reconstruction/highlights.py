"""The scene radiance from the captures by least squares: clipped highlights recovered from the streak.

Where the uncoded (plain) capture clips, its pixels say only "brighter than full well". The coded half spreads
each highlight along the streak into many pixels that stay below clipping, each a scaled copy of the
highlight, so with the coded capture the highlight radiance is the solution of a linear problem:

- start ``x0``: the reference capture divided by its half's light fraction (its PSF sum), and the clipping
  level ``1 / fraction`` where it clips (any channel, grown by one pixel);
- unknowns: every pixel of the frame and of a margin of half a PSF window around it (the light that enters the
  frame from outside; edge-replicated at the start); the FFT canvas is grown to a fast length, its extra
  pixels out of reach of the frame;
- least squares: ``x`` minimises ``Σ_v ‖M_v (p_v ∗ x − y_v)‖²`` over views ``v``, where ``M_v`` keeps only the
  view's unclipped pixels: conjugate gradients on the normal equations (CGLS) from ``x0`` with Jacobi
  preconditioning (each unknown scaled by its column norm; unknowns whose light reaches no kept pixel stay
  at the start), stopped after ``iters`` iterations or when the residual reaches rounding level;
- bounded stage (``bound_iters`` > 0, the shipped networks): a clipped pixel says more than nothing — it
  received at least full well. Far along a bright highlight's streak that is a strong lower bound on the
  highlight (the streak is weak there). ``bound_rounds`` CGLS restarts over every view the solve may use,
  each from the previous estimate projected onto [0, 2^8], with the clipped coded pixels that the estimate
  leaves below the clipping level added as data at that level (an active set for the bound
  ``p_c ∗ x ≥ full well``). Before it, the least-squares stage uses the coded view alone, from the coded
  capture's start, when the solve may use it (the streak sets the interiors the plain capture clips); without
  a bounded stage it uses every view from the uncoded capture's start, if the solve may use it.
  The plain capture's clipped pixels are not used as bounds: next to its compact PSF they bound nothing the
  start does not, and as data they let weakly-seen unknowns overshoot.
- numerical limit: where both captures clip, the data bound the radiance from below only, and the bounded
  stage's result there can follow rounding (float32 and float64 solves may differ at those pixels by far more
  than where a capture measures the pixel; ``tests/reconstruction/test_highlights.py`` checks a synthetic
  case of the latter).

Measured on 12 held-out HDR test scenes of 256² (``benchmarks/hdr_solve.py``, highlight PSNR with peak 2^8):
see ``benchmarks/results/hdr_solve.json`` and the README.
The HDR networks take the solve from the captures their variant sees as their input and the baseline their
output refines (``hdrnet.HDRNet(highlight_iters=N, bound_iters=…, bound_rounds=…)``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from doefab.errors import DoefabError
from doefab.imaging.captures import fft_length
from doefab.reconstruction.wiener import psf_to_otf

__all__ = ["solve_highlights", "highlight_support", "VIEWS", "CLIPPED"]


VIEWS = ("coded", "uncoded")
CLIPPED = 0.98  # a capture at or above this fraction of full scale is taken as clipped


def highlight_support(capture: torch.Tensor, clipped: float = CLIPPED, grow_px: int = 1) -> torch.Tensor:
    """[B, 1, H, W] 1 where ``capture`` clips in any channel, grown by ``grow_px`` pixels."""
    s = (capture >= clipped).any(dim=1, keepdim=True).to(capture.dtype)
    return F.max_pool2d(s, 2 * grow_px + 1, 1, grow_px) if grow_px else s


def solve_highlights(coded: torch.Tensor, uncoded: torch.Tensor, psf_coded: torch.Tensor,
                     psf_uncoded: torch.Tensor, iters: int = 40, views: tuple[str, ...] = VIEWS,
                     clipped: float = CLIPPED, dtype: torch.dtype = torch.float32, bound_iters: int = 0,
                     bound_rounds: int = 8) -> torch.Tensor:
    """[B, 3, H, W] least-squares radiance in [0, 2^8] (module docstring).

    Args:
        coded, uncoded: [B, 3, H, W] captures in [0, 1].  psf_coded, psf_uncoded: [3, K, K] RGB PSFs (each
            carrying its half's share of the light, as simulated).  iters: CGLS iterations of the least-squares
            stage (0: the clipping level).  views: the captures the solve may use — both (the proposed network),
            or one of them (the ablations).  dtype: of the iterations (float64 for convergence studies).
            bound_iters, bound_rounds: CGLS iterations of the bounded stage, split over that many restarts
            (0: no bounded stage, and the least-squares stage uses every view from the reference's start).
    """
    if coded.ndim != 4 or coded.shape != uncoded.shape or coded.shape[1] != 3:
        raise DoefabError(f"captures must be two [B, 3, H, W] tensors, got {tuple(coded.shape)}, {tuple(uncoded.shape)}")
    if psf_coded.shape != psf_uncoded.shape or psf_coded.ndim != 3 or psf_coded.shape[0] != 3:
        raise DoefabError(f"PSFs must be two [3, K, K] tensors, got {tuple(psf_coded.shape)}, {tuple(psf_uncoded.shape)}")
    if iters < 0 or bound_iters < 0 or bound_rounds < 1:
        raise DoefabError(f"iters and bound_iters must be ≥ 0 and bound_rounds ≥ 1, got {iters}, {bound_iters}, "
                          f"{bound_rounds}")
    if not views or any(v not in VIEWS for v in views):
        raise DoefabError(f"views must be a non-empty subset of {VIEWS}, got {views!r}")
    with torch.no_grad():
        h, w = coded.shape[-2:]
        m = psf_coded.shape[-1] // 2
        # the canvas: frame + margin, grown to a fast FFT length (606 for 512 px: 640); the extra pixels lie
        # more than m from the frame both ways round, so no light crosses
        big = (fft_length(h + 2 * m), fft_length(w + 2 * m))
        pad = (m, big[1] - w - m, m, big[0] - h - m)
        caps = {"coded": coded.to(dtype), "uncoded": uncoded.to(dtype)}
        psfs = {"coded": psf_coded.to(dtype), "uncoded": psf_uncoded.to(dtype)}
        # the first stage: every view from the plain capture's start, or (with a bounded stage after it) the
        # streak alone from the coded capture's start — it sets the interiors that the plain capture clips
        first = views if not bound_iters else (("coded",) if "coded" in views else views)
        ref = "uncoded" if "uncoded" in first else "coded"
        otf = {k: psf_to_otf(psfs[k], big) for k in views}
        otf_conj = {k: o.conj().resolve_conj() for k, o in otf.items()}  # the adjoint's, materialised once
        otf_sq = {k: psf_to_otf(torch.flip(psfs[k] ** 2, (-2, -1)), big) for k in views}
        share = psfs[ref].sum(dim=(-2, -1)).clamp_min(1e-6).view(1, 3, 1, 1)
        support = highlight_support(caps[ref], clipped)
        x0 = torch.where(support > 0, (1.0 / share).expand_as(caps[ref]), caps[ref] / share)  # start at clipping
        # the scene beyond the frame: edge-replicated (light from just outside enters the frame)
        x = F.pad(x0, pad, mode="replicate")
        keep = {k: F.pad((caps[k] < clipped).to(dtype), pad) for k in views}
        ys = {k: F.pad(caps[k], pad) * keep[k] for k in views}
        # each view's column norms² over its unclipped pixels (Jacobi preconditioner), reused by every restart
        cols = {k: torch.fft.irfft2(torch.fft.rfft2(keep[k]) * otf_sq[k], s=big) for k in views}
        x = _cgls(x, {k: keep[k] for k in first}, {k: ys[k] for k in first}, {k: cols[k] for k in first},
                  (otf, otf_conj), big, iters, dtype)
        if bound_iters:
            # bounds from the coded capture only (module docstring: the plain one's bound nothing the start does not)
            over = {"coded": F.pad((caps["coded"] >= clipped).to(dtype), pad)} if "coded" in views else {}
            per = [bound_iters // bound_rounds + (r < bound_iters % bound_rounds) for r in range(bound_rounds)]
            for n in per:
                x = x.clamp(0.0, 256.0)
                fx = torch.fft.rfft2(x)
                pred = {k: torch.fft.irfft2(fx * otf[k], s=big) for k in views}
                mask, data, col = dict(keep), dict(ys), dict(cols)
                for k, o in over.items():  # clipped coded pixels the estimate leaves below full well
                    low = o * (pred[k] < clipped).to(dtype)
                    mask[k], data[k] = keep[k] + low, ys[k] + clipped * low
                    col[k] = cols[k] + torch.fft.irfft2(torch.fft.rfft2(low) * otf_sq[k], s=big)
                x = _cgls(x, mask, data, col, (otf, otf_conj), big, n, dtype, pred)
        return x[..., m:m + h, m:m + w].clamp(0.0, 256.0).to(coded.dtype)


def _cgls(x0, mask, data, cols, otfs, big, iters, dtype, pred=None):
    """``iters`` Jacobi-preconditioned CGLS iterations of min Σ_v ‖mask_v (p_v ∗ x − data_v)‖² from ``x0``.
    ``cols``: per view, each unknown's squared column norm over the masked pixels, ``(mask_v ⋆ p_v²)``;
    ``otfs``: (OTFs, their complex conjugates), each a dict per view; ``pred``: per view, ``p_v ∗ x0`` if already
    computed."""
    views = tuple(mask)
    otf, otf_conj = otfs
    # Jacobi preconditioning: each unknown scaled by 1 / its column norm ‖A e_j‖ (the light of pixel j that
    # lands on the pixels the views keep) — pixels deep inside a large clipped blob reach few of them and would
    # otherwise converge last.
    norm2 = sum(cols[k] for k in views)
    # unknowns whose light reaches (almost) no kept pixel stay at the start: nothing measures them
    seen = norm2 > 1e-6 * norm2.amax(dim=(-2, -1), keepdim=True)
    scale = seen / norm2.clamp_min(1e-30).sqrt()

    def fwd(z):
        fx = torch.fft.rfft2(z * scale)
        return {k: torch.fft.irfft2(fx * otf[k], s=big) * mask[k] for k in views}

    def adj(r):
        acc = sum(torch.fft.rfft2(r[k]) * otf_conj[k] for k in views)  # r is zero where a view is not kept
        return torch.fft.irfft2(acc, s=big) * scale

    def dot(a, c):
        return (a * c).sum(dim=(1, 2, 3), keepdim=True)

    z = torch.zeros_like(x0)
    if pred is None:
        fx0 = torch.fft.rfft2(x0)
        pred = {k: torch.fft.irfft2(fx0 * otf[k], s=big) for k in views}
    r = {k: data[k] - pred[k] * mask[k] for k in views}
    s = adj(r)
    p, gamma = s, dot(s, s)
    # an image whose normal-equation residual has fallen to rounding level stops (CGLS breaks down there)
    floor = gamma * (100.0 * torch.finfo(dtype).eps) ** 2
    for i in range(iters):
        q = fwd(p)
        alpha = torch.where(gamma > floor, gamma / sum(dot(q[k], q[k]) for k in views).clamp_min(1e-30), 0.0)
        z.add_(alpha * p)
        if i == iters - 1:
            break  # the last step's residual and direction would go unused: their adjoint (FFTs) is not computed
        for k in views:
            r[k].sub_(alpha * q[k])
        s = adj(r)
        g_new = dot(s, s)
        p, gamma = s + g_new / gamma.clamp_min(1e-30) * p, g_new
    return x0 + z * scale
