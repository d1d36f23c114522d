"""What a reconstruction of measured captures says beside its result: where the captures cannot hold what the
network needs — a frame smaller than the PSF window, pixels clipped in both views, or views that look swapped. Each
note is a sentence (None where there is nothing to say), printed by ``doefab reconstruct`` and kept in its
``reconstruct.json``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["small_frame_note", "clipped_note", "swapped_note", "view_mismatch", "channel_psfs", "MOST_CLIPPED_BOTH",
           "SWAPPED_RATIO", "SIDE_PX"]


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
    the channels, each side less its mean per channel; a common gain of a view leaves it alone), over the pixels
    whose PSF window holds no clipped pixel; each the least over the PSF's planes. ``coded``,
    ``uncoded``: [3, H, W] views in [0, 1]; ``pc``, ``pu``: (planes, 3, K, K) from :func:`channel_psfs`. NaN where
    no pixel is usable or the frame holds no structure.

    Example: ``view_mismatch(c, u, pc, pu)[0]`` is 0 for noiseless views rendered with ``pc``, ``pu`` at one plane."""
    from scipy.signal import fftconvolve

    from doefab.reconstruction.highlights import CLIPPED

    k = pc.shape[-1]
    h, w = coded.shape[1:]
    r0, c0 = max((h - SIDE_PX) // 2, 0), max((w - SIDE_PX) // 2, 0)
    views = [np.asarray(v, np.float64)[:, r0:r0 + SIDE_PX, c0:c0 + SIDE_PX] for v in (coded, uncoded)]
    clipped = ((views[0] >= CLIPPED) | (views[1] >= CLIPPED)).any(axis=0).astype(np.float64)
    usable = fftconvolve(clipped, np.ones((k, k)), mode="valid") < 0.5
    if not usable.any():
        return math.nan, math.nan

    def off(a, pa, b, pb) -> float:
        x, y = fftconvolve(a[None], pa, mode="valid", axes=(-2, -1)), fftconvolve(b[None], pb, mode="valid",
                                                                                   axes=(-2, -1))
        x, y = x[..., usable], y[..., usable]
        x, y = x - x.mean(axis=-1, keepdims=True), y - y.mean(axis=-1, keepdims=True)
        xx, yy, xy = ((a * b).sum(axis=(1, 2)) for a, b in ((x, x), (y, y), (x, y)))
        ok = np.minimum(xx, yy) > 1e-12 * max(float(xx.max()), float(yy.max()), 1e-30)
        return float(np.min(1.0 - xy[ok] ** 2 / (xx[ok] * yy[ok]))) if ok.any() else math.nan
    return off(views[0], pu, views[1], pc), off(views[1], pu, views[0], pc)


def swapped_note(coded: np.ndarray, uncoded: np.ndarray, pair) -> str | None:
    """Views that fit the split aperture's identity (:func:`view_mismatch`) at most ``SWAPPED_RATIO`` as far off
    swapped as stated: the coded and plain captures were most likely given the wrong way round. None where they fit
    as stated, the frame is smaller than the PSF window or holds nothing to tell by. ``pair``: the PSFs the network
    is told (its own or ``--psf``'s).

    Example: ``swapped_note(plain_view, coded_view, rec.pair)`` names the swap for views of a textured scene."""
    pc, pu = channel_psfs(pair)
    if min(coded.shape[1:]) <= pc.shape[-1]:
        return None
    stated, swapped = view_mismatch(coded, uncoded, pc, pu)
    if not swapped <= SWAPPED_RATIO * stated:  # NaN: nothing to tell by
        return None
    return (f"the coded and plain captures look swapped: the coded one convolved with the plain half's PSF and the "
            f"plain one with the coded half's leave {stated:.0%} of their variance unexplained by each other, "
            f"{swapped:.0%} the other way round; check --coded and --uncoded (the coded view is the one recorded "
            f"through the DOE's half)")
