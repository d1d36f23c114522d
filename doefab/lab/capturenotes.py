"""What a reconstruction of measured captures says beside its result: where the captures cannot hold what the
network needs — a frame smaller than the PSF window, or pixels clipped in both views. Each note is a sentence (None
where there is nothing to say), printed by ``doefab reconstruct`` and kept in its ``reconstruct.json``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["small_frame_note", "clipped_note", "MOST_CLIPPED_BOTH"]


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
