"""Sampling of the split pupil: which DOE pixels each half uses, their clear-aperture coverage, and the
smooth optical path of a point source relative to the plane in focus.

Array convention used everywhere in doefab: a 2-D map over the DOE grid is indexed ``[row, column]``;
row 0 is the top (largest y), column 0 the left (most negative x), looking from the scene into the
camera (x right, y up). The coded half is x < 0 (the paper's Eq. 3), i.e. the left columns.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError
from doefab.optics.camera import Camera

__all__ = ["PupilHalf", "pupil_half", "source_path_difference", "cell_coverage", "HALVES", "APERTURES"]

HALVES = ("coded", "uncoded")
APERTURES = HALVES + ("full",)  # "full": the whole clear aperture, one coherent pupil (reference cases)
_EDGE_SUBSAMPLES = 16  # sub-samples per axis used to integrate the coverage of rim pixels


@dataclass(frozen=True)
class PupilHalf:
    """Sample geometry of one aperture half.

    Attributes:
        half: ``"coded"`` (x < 0), ``"uncoded"`` (x > 0) or ``"full"`` (whole aperture, one coherent pupil).
        rows, cols: slices of the DOE grid (DOE pixel indices) that hold this half's light.
        oversample: pupil samples per DOE pixel and axis (q).
        pitch: sample pitch b = doe_pitch / q, metres.
        x: (Nx,) sample-centre x coordinates, metres.  y: (Ny,) sample-centre y coordinates (descending).
        coverage: (Ny, Nx) float64 fraction of each sample's area inside the half-disk.
        full_area: area of the whole (both halves) clear aperture as sampled, m² (normalises energy to 1).
    """

    half: str
    rows: slice
    cols: slice
    oversample: int
    pitch: float
    x: np.ndarray
    y: np.ndarray
    coverage: np.ndarray
    full_area: float

    @property
    def r2(self) -> np.ndarray:
        """(Ny, Nx) squared radius of each sample centre, m²."""
        return self.y[:, None] ** 2 + self.x[None, :] ** 2


def cell_coverage(xc: np.ndarray, yc: np.ndarray, b: float, radius: float, side: int, split: float = 0.0) -> np.ndarray:
    """Fraction of each b × b cell (centres xc × yc) inside the disk and the half-plane side·(x − split) > 0.

    ``side`` is -1 (x < split), +1 (x > split) or 0 (no half-plane). Cells inside or outside the disk are
    exact, and so is the split line's cut of an interior cell (its area fraction, a linear function of
    ``split``); rim cells are integrated with 16 × 16 sub-samples, each sub-column weighted by the exact
    fraction of it on this side of the split.
    """
    r = np.sqrt(yc[:, None] ** 2 + xc[None, :] ** 2)
    half_diag = b / math.sqrt(2.0)
    inside = r + half_diag <= radius
    outside = r - half_diag >= radius
    cov = inside.astype(np.float64)
    if side != 0:
        x0 = xc - b / 2
        frac = np.clip((split - x0) / b, 0.0, 1.0) if side < 0 else np.clip(1.0 - (split - x0) / b, 0.0, 1.0)
        cov *= frac[None, :]
    edge = ~inside & ~outside
    ii, jj = np.nonzero(edge)
    if ii.size:
        s = (np.arange(_EDGE_SUBSAMPLES) + 0.5) / _EDGE_SUBSAMPLES - 0.5
        sy = yc[ii][:, None, None] + b * s[None, :, None]
        sx = xc[jj][:, None, None] + b * s[None, None, :]
        ok = (sx**2 + sy**2 < radius**2).astype(np.float64)
        if side != 0:  # exact share of each sub-column on this side
            w = b / _EDGE_SUBSAMPLES
            f = np.clip((split - (sx - w / 2)) / w, 0.0, 1.0)
            ok *= f if side < 0 else 1.0 - f
        cov[ii, jj] = ok.mean(axis=(1, 2))
    return cov


def pupil_half(camera: Camera, half: str, oversample: int = 1, split: float = 0.0, margin: float = 0.0) -> PupilHalf:
    """Sample geometry of one half of the pupil at ``oversample`` samples per DOE pixel and axis.

    ``split`` (metres): where the dual-pixel split line crosses the DOE grid (x = 0 when the DOE is centred on
    the lens axis; a decentered die moves it). ``margin`` (metres): also sample the columns up to this far
    beyond the centre line, so that splits within ±margin share one sample grid (and one set of transform
    matrices).
    """
    if half not in APERTURES:
        raise DoefabError(f"half must be one of {APERTURES}, got {half!r}")
    if not isinstance(oversample, int) or oversample < 1:
        raise DoefabError(f"pupil oversample must be an integer ≥ 1, got {oversample!r}")
    if not (math.isfinite(split) and math.isfinite(margin) and margin >= 0 and abs(split) <= margin + 1e-15):
        raise DoefabError(f"the split line at {split:g} m must lie within the sampled margin ±{margin:g} m")
    n, a, radius = camera.doe_pixels, camera.doe_pitch, camera.aperture_diameter / 2
    centres = (np.arange(n) - (n - 1) / 2) * a  # DOE pixel centres, metres (x ascending)
    # DOE pixels that can hold light of this half (touching the disk and the half-plane)
    touch = np.abs(centres) - a / 2 < radius
    if half == "coded":
        cols_ok = touch & (centres - a / 2 < margin)
    elif half == "uncoded":
        cols_ok = touch & (centres + a / 2 > -margin)
    else:
        cols_ok = touch
    cidx = np.nonzero(cols_ok)[0]
    ridx = np.nonzero(touch)[0]
    cols = slice(int(cidx[0]), int(cidx[-1]) + 1)
    rows = slice(int(ridx[0]), int(ridx[-1]) + 1)
    q, b = oversample, a / oversample
    sub = (np.arange(q) - (q - 1) / 2) * b
    x = (centres[cols][:, None] + sub[None, :]).ravel()
    y = (-(centres[rows])[:, None] + sub[None, ::-1]).ravel()  # row 0 = top = largest y
    side = {"coded": -1, "uncoded": 1, "full": 0}[half]
    cov = cell_coverage(x, y, b, radius, side, split)
    return PupilHalf(half, rows, cols, q, b, x, y, cov, _disk_area(camera, q))


@functools.lru_cache(maxsize=16)
def _disk_area(camera: Camera, oversample: int) -> float:
    """The whole clear aperture's area as sampled (m²): both halves together normalise the energy to 1."""
    n, a = camera.doe_pixels, camera.doe_pitch
    b = a / oversample
    sub = (np.arange(oversample) - (oversample - 1) / 2) * b
    x = (((np.arange(n) - (n - 1) / 2) * a)[:, None] + sub[None, :]).ravel()
    return float(cell_coverage(x, -x, b, camera.aperture_diameter / 2, 0).sum() * b * b)


def source_path_difference(r2: np.ndarray, depth: float, focus_distance: float) -> np.ndarray:
    """Optical path (metres) of an on-axis point at ``depth`` across the pupil, relative to the plane in focus.

    The exact spherical wavefront of the paper's Eq. 1, ``sqrt(r² + z²) − z``, minus the one the lens images
    perfectly onto the sensor (from ``focus_distance``); ``inf`` is a plane wave. Written as
    ``r² / (sqrt(r² + z²) + z)`` so that it keeps full precision for distant points.

    Args:
        r2: squared pupil radius, m², any shape.
        depth: source distance z > 0 in metres, or ``inf``.
        focus_distance: camera focus distance in metres, or ``inf``.
    Returns:
        float64 array of r2's shape, metres.
    """

    def sag(z: float) -> np.ndarray:
        if math.isinf(z):
            return np.zeros_like(r2)
        return r2 / (np.sqrt(r2 + z * z) + z)

    return sag(depth) - sag(focus_distance)
