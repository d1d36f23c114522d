"""What a fab can make, in one place: how many height levels (L = 2, 4, 8, 16 or 32, made with M = log2 L binary
masks) and how small a feature (the minimum feature, checked against the DOE pitch).

A design records its L (``design.json`` ``n_levels``; a record without it was made for 16 levels, the prototype's
4-mask process); quantization, the mask export and its verification, and the tolerance relief all follow it.
"""

from __future__ import annotations

import math

from doefab.validate import length_m
from doefab.errors import DoefabError

__all__ = ["LEVEL_CHOICES", "DEFAULT_LEVELS", "MAX_MASKS", "check_levels", "mask_count", "check_min_feature"]

LEVEL_CHOICES = (2, 4, 8, 16, 32)
DEFAULT_LEVELS = 16  # the prototype's process (4 masks); design records without n_levels mean this
MAX_MASKS = int(math.log2(max(LEVEL_CHOICES)))


def check_levels(n_levels, what: str = "levels") -> int:
    """``n_levels`` as an int when a fab can make it (a power of two, 2–32), else one error naming the choices."""
    if isinstance(n_levels, bool) or not isinstance(n_levels, int) or n_levels not in LEVEL_CHOICES:
        raise DoefabError(f"{what} = {n_levels!r}: a mask process makes L = 2, 4, 8, 16 or 32 levels (log2 L binary "
                          f"masks, mask m etching 2^m level steps); choose one of {', '.join(map(str, LEVEL_CHOICES))}")
    return n_levels


def mask_count(n_levels: int) -> int:
    """M = log2 L binary masks for ``n_levels`` levels."""
    return check_levels(n_levels).bit_length() - 1


def check_min_feature(doe_pitch: float, min_feature: float) -> float:
    """Refuse a DOE pitch (metres) finer than the fab's minimum feature (metres); return pitch / min feature.

    A single DOE pixel is the smallest feature a level map can hold (an isolated pixel on some mask), so every
    feature of every mask is at least the pitch wide when pitch ≥ minimum feature.
    """
    pitch = length_m("DOE pitch", doe_pitch, 1e-8, 1e-2)
    feature = length_m("minimum feature", min_feature, 1e-8, 1e-3, what="minimum features")
    if pitch < feature * (1 - 1e-9):
        raise DoefabError(f"the DOE pitch {pitch * 1e6:.4g} µm is finer than the fab's minimum feature "
                          f"{feature * 1e6:.4g} µm: an isolated DOE pixel could not be made; use a DOE pitch of at "
                          f"least {feature * 1e6:.4g} µm (doe_pitch_um) or a fab with a finer minimum feature "
                          f"(min_feature_um)")
    return pitch / feature
