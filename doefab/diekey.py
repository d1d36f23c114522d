"""The DOE die's key: its outline, a rectangle whose two corners on the DOE's coded half are chamfered, the
larger at +y, so that the die fits its holder's pocket one way only (not turned, not flipped: no symmetry of the
rectangle maps the pair of unequal chamfers onto itself). One outline for the mask set (the dicing outline, layer
100) and for the holder (its pocket), in whatever unit the caller uses.

Seen from the DOE's patterned face (the mask layout's view) the coded half lies at x > 0 when that face is toward
the lens and at x < 0 when it is toward the scene; seen from the lens side (the holder's pocket) always at x > 0.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["die_outline", "DEFAULT_CHAMFER_MM", "DEFAULT_THICKNESS_MM", "SECOND_CHAMFER", "KEY_PROUD_MM",
           "LEAST_CLEARANCE_MM", "least_key_chamfer_mm", "chamfer_problem"]

DEFAULT_CHAMFER_MM = 2.0  # the larger chamfer's leg (mm)
DEFAULT_THICKNESS_MM = 1.0  # the die's substrate thickness (mm): the mask set's substrate, the holder's pocket depth
SECOND_CHAMFER = 0.5  # the smaller chamfer's leg, a fraction of the larger
KEY_PROUD_MM = 0.1  # how far a turned-over die's corner must stand into the pocket's keyed wall (it cannot go in)
LEAST_CLEARANCE_MM = 0.05  # the holder's tightest pocket clearance per side (a printed pocket takes no less)


def die_outline(width: float, height: float, chamfer: float, coded_sign: int = 1) -> np.ndarray:
    """(N, 2) counter-clockwise outline of a ``width`` × ``height`` die centred on the origin, the corners of the
    coded half (x > 0 for ``coded_sign`` = 1, x < 0 for −1) chamfered with legs ``chamfer`` (at +y) and
    ``SECOND_CHAMFER`` × ``chamfer`` (at −y); a plain rectangle for ``chamfer`` = 0. Units: the caller's.

    Example:
        >>> die_outline(12.0, 12.0, 2.0).round(2).tolist()
        [[-6.0, -6.0], [5.0, -6.0], [6.0, -5.0], [6.0, 4.0], [4.0, 6.0], [-6.0, 6.0]]
    """
    w, h, c, c2 = width / 2, height / 2, chamfer, SECOND_CHAMFER * chamfer
    if chamfer <= 0:
        pts = np.array([[-w, -h], [w, -h], [w, h], [-w, h]], float)
    else:
        pts = np.array([[-w, -h], [w - c2, -h], [w, -h + c2], [w, h - c], [w - c, h], [-w, h]], float)
    if coded_sign < 0:  # the mirror image, still counter-clockwise
        pts = pts[::-1] * [-1.0, 1.0]
    return pts


def chamfer_problem(die_mm: float, chamfer_mm: float) -> str:
    """Why a die key's larger chamfer ``chamfer_mm`` cannot be cut on a square die of ``die_mm`` (it must stay below
    half the die), or ''. Example: ``chamfer_problem(6, 3.5)`` names 1.5 mm (a quarter of the die)."""
    if chamfer_mm < die_mm / 2:
        return ""
    return (f"die chamfer {chamfer_mm:g} mm must be below half the die ({die_mm / 2:g} mm): give a smaller one, e.g. "
            f"{die_mm / 4:g} mm")


def least_key_chamfer_mm(clearance_mm: float) -> float:
    """The least ``die_chamfer_mm`` that keys the die in a pocket ``clearance_mm`` wider all round: a die turned or
    flipped puts a square corner where the pocket has the smaller chamfer, or the smaller chamfer where it has the
    larger; that corner, s·c/√2 or (1 − s)·c/√2 beyond the pocket's chamfer, must stand proud of it by
    ``KEY_PROUD_MM`` however the die slides in the pocket (√2 × the clearance along the diagonal, and the clearance
    itself). Example: ``round(least_key_chamfer_mm(0.25), 2)`` → 1.99."""
    reach = ((1 + math.sqrt(2)) * clearance_mm + KEY_PROUD_MM) * math.sqrt(2)
    return reach / min(SECOND_CHAMFER, 1 - SECOND_CHAMFER)
