"""What a reconstruction of measured captures says beside its result: where the captures cannot hold what the
network needs — a frame smaller than the PSF window, pixels clipped in both views, or views that look swapped. Each
note is a sentence (None where there is nothing to say), printed by ``doefab reconstruct`` and kept in its
``reconstruct.json``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["small_frame_note", "clipped_note", "swapped_note", "view_mismatch", "channel_psfs", "MOST_CLIPPED_BOTH",
           "looks_swapped", "SWAPPED_RATIO", "SWAPPED_GAP", "SIDE_PX"]


def small_frame_note(rec, size_hw: tuple[int, int], psf=None) -> str | None:
    """A frame whose shorter side is below the PSF window the network reads (the measured ``psf``'s where given):
    the light the DOE spreads past the frame's edges is missing from its captures. None where it is not.

    Example: ``small_frame_note(load_reconstructor("hyperspectral"), (96, 96))`` names the 191 px window."""
    k = int((psf if psf is not None else rec.pair).coded.shape[-1])
    h, w = size_hw
    if min(h, w) >= k:
        return None
    return (f"the frame is {w}×{h} px, under the {k} px PSF window the {rec.task} network reads: light the DOE "
            f"spreads past the frame's edges is missing from the captures, so the result is less reliable, the more "
            f"so the smaller the frame; capture (or crop) at least {k} px on each side")


MOST_CLIPPED_BOTH = 0.01  # the share of a frame's pixels clipped in both views above which it is warned of


def clipped_note(coded: np.ndarray, uncoded: np.ndarray) -> str | None:
    """A frame whose pixels clip (any channel at ``highlights.CLIPPED`` of full scale or above) in both views on
    more than ``MOST_CLIPPED_BOTH`` of it: neither capture measures the scene there (the HDR solve bounds its radiance
    from below only). None where it is not. ``coded``, ``uncoded``: [3, H, W] captures in [0, 1].

    Example: ``clipped_note(np.ones((3, 8, 8)), np.ones((3, 8, 8)))`` names 100 % of the pixels."""
    from doefab.reconstruction.highlights import CLIPPED

    both = float(np.mean((np.asarray(coded) >= CLIPPED).any(axis=0) & (np.asarray(uncoded) >= CLIPPED).any(axis=0)))
    if both <= MOST_CLIPPED_BOTH:
        return None
    return (f"{both:.1%} of the pixels clip in both captures: neither view measures the scene there, so the result "
            f"is a lower bound at best (HDR radiance) or a guess (spectra, depth); capture with a shorter exposure")


SWAPPED_RATIO = 0.5  # the views swapped must fit at most this fraction as far off as stated to be warned of
SWAPPED_GAP = 0.005  # ... and closer by more than this share of the variance
SIDE_PX = 512  # the central square of a frame the check reads (sensor px)


def channel_psfs(pair) -> tuple[np.ndarray, np.ndarray]:
    """(planes, 3, K, K) coded and plain PSFs per colour channel: a pair's own three bands, or its bands weighted by
    the default sensor response (a flat spectrum), each channel's weights summing to 1.

    Example: ``channel_psfs(load_reconstructor("hyperspectral").pair)[0].shape`` is (1, 3, 191, 191)."""
    c, u = (np.asarray(v, np.float64) for v in (pair.coded, pair.uncoded))
    if c.shape[1] != 3:
        from doefab.imaging.sensor import sensor_response

        r = np.asarray(sensor_response(pair.wavelengths), np.float64)
        r = r / r.sum(axis=1, keepdims=True)
        c, u = np.einsum("cw,dwij->dcij", r, c), np.einsum("cw,dwij->dcij", r, u)
    return c, u


def view_mismatch(coded: np.ndarray, uncoded: np.ndarray, pc: np.ndarray, pu: np.ndarray) -> tuple[float, float]:
    """(as stated, swapped): how far the two views break the split aperture's identity coded ⊛ PSF_plain =
    plain ⊛ PSF_coded (both are the scene through both halves): 1 − r² of the two sides (r: their correlation over
    the channels, each side less its mean per channel, 0 where negative; a common gain of a view leaves it alone),
    over the pixels whose PSF window holds no clipped or non-finite pixel, in the frame's central square of
    ``SIDE_PX`` (or twice the window); each the least over the PSF's planes. ``coded``, ``uncoded``: [3, H, W] views
    in [0, 1]; ``pc``, ``pu``: (planes, 3, K, K) from :func:`channel_psfs`. NaN where no pixel is usable (a frame no
    wider than the window among them) or the frame holds no structure.

    Example: ``view_mismatch(c, u, pc, pu)[0]`` is 0 for noiseless views rendered with ``pc``, ``pu`` at one plane."""
    import torch

    from doefab.imaging.captures import convolve_valid
    from doefab.reconstruction.highlights import CLIPPED

    k, side = pc.shape[-1], max(SIDE_PX, 2 * pc.shape[-1])
    h, w = coded.shape[1:]
    if min(h, w) <= k:
        return math.nan, math.nan
    r0, c0 = max((h - side) // 2, 0), max((w - side) // 2, 0)
    views = [torch.tensor(np.asarray(v)[:, r0:r0 + side, c0:c0 + side], dtype=torch.float64) for v in (coded, uncoded)]
    bad = torch.zeros(views[0].shape[1:], dtype=torch.bool)
    for v in views:
        bad |= ~torch.isfinite(v).all(dim=0) | (v >= CLIPPED).any(dim=0)
    for v in views:
        v[:, bad] = 0.0
    usable = (convolve_valid(bad[None].double(), torch.ones(1, k, k, dtype=torch.float64))[0] < 0.5).numpy()
    if not usable.any():
        return math.nan, math.nan
    pc, pu = torch.as_tensor(pc, dtype=torch.float64), torch.as_tensor(pu, dtype=torch.float64)

    def off(a, pa, b, pb) -> float:
        x, y = (convolve_valid(v[None], p).numpy()[..., usable] for v, p in ((a, pa), (b, pb)))
        level = (x.mean(axis=-1) ** 2).sum(axis=1) * x.shape[-1] + (y.mean(axis=-1) ** 2).sum(axis=1) * y.shape[-1]
        x, y = x - x.mean(axis=-1, keepdims=True), y - y.mean(axis=-1, keepdims=True)
        xx, yy, xy = ((a * b).sum(axis=(1, 2)) for a, b in ((x, x), (y, y), (x, y)))
        ok = np.minimum(xx, yy) > 1e-8 * level + 1e-30  # structure above the FFT's rounding of a flat frame
        r2 = np.maximum(xy[ok], 0.0) ** 2 / (xx[ok] * yy[ok])
        return float(np.min(1.0 - r2)) if ok.any() else math.nan
    return off(views[0], pu, views[1], pc), off(views[1], pu, views[0], pc)


def looks_swapped(stated: float, swapped: float) -> bool:
    """Whether views that break the identity by ``stated`` as given and ``swapped`` the other way round
    (:func:`view_mismatch`) were given the wrong way round: swapped at most ``SWAPPED_RATIO`` of stated and closer by
    more than ``SWAPPED_GAP`` (not a difference within rounding). False where either is NaN.

    Example: ``looks_swapped(0.6, 0.1)`` is True; ``looks_swapped(0.004, 0.001)`` is False."""
    from doefab.lab.viewcheck import clearly_better

    return clearly_better(stated, swapped, SWAPPED_RATIO, SWAPPED_GAP)


def swapped_note(coded: np.ndarray, uncoded: np.ndarray, pair) -> str | None:
    """Views that :func:`looks_swapped` calls swapped: the coded and plain captures were most likely given the
    wrong way round. None where they fit as given, or where the frame holds nothing to tell by (no wider than the PSF
    window, clipped within every window, without structure). ``pair``: the PSFs the network is told (its own or
    ``--psf``'s).

    Example: ``swapped_note(plain_view, coded_view, rec.pair)`` names the swap for views of a textured scene."""
    pc, pu = channel_psfs(pair)
    stated, swapped = view_mismatch(coded, uncoded, pc, pu)
    if not looks_swapped(stated, swapped):
        return None
    return (f"the coded and plain captures look swapped: the coded one convolved with the plain half's PSF and the "
            f"plain one with the coded half's leave {stated:.0%} of their variance unexplained by each other, "
            f"{swapped:.0%} the other way round; check --coded and --uncoded (the coded view is the one recorded "
            f"through the DOE's half)")
