"""Level map → M = log2 L binary etch masks → exact Manhattan rectangles, and back.

Convention (DESIGN-NOTES; kept here and in ``levels``): mask m (m = 0..M−1) etches depth 2^m·d, and a pixel is
etched by mask m when bit m of (L − 1 − level) is set, so level = L − 1 − Σ 2^m·etched_m (L = 16: 4 masks).

Rectangles come from vectorised run-lengths per row, merged down the rows wherever consecutive rows hold
the same run: exact pixel edges, no per-pixel squares (except truly isolated pixels), no contour tracing.
"""

from __future__ import annotations

import numpy as np

from doefab.errors import DoefabError
from doefab.fabrication.process import DEFAULT_LEVELS, mask_count

__all__ = ["validate_levels", "bit_planes", "bit_plane", "levels_from_planes", "plane_rectangles",
           "rasterize_rectangles", "rasterize_manhattan"]


def validate_levels(levels, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """Return ``levels`` as a uint8 (N, M) array of levels 0..n_levels−1, or raise a DoefabError naming the problem."""
    top = n_levels - 1
    arr = np.asarray(levels)
    if arr.ndim != 2 or min(arr.shape) == 0:
        raise DoefabError(f"level map must be a non-empty 2-D array, got shape {arr.shape}")
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)):
            raise DoefabError(f"level map contains NaN or infinite values: levels must be integers 0..{top}")
        if not np.all(arr == np.round(arr)):
            raise DoefabError(f"level map holds non-integer values: levels must be integers 0..{top} (quantize first)")
    elif arr.dtype.kind not in "iub":
        raise DoefabError(f"level map must be an integer array, got dtype {arr.dtype}")
    if arr.min() < 0 or arr.max() > top:
        raise DoefabError(f"level values must lie in 0..{top} ({n_levels} levels), found {arr.min()}..{arr.max()}")
    return arr.astype(np.uint8)


def bit_planes(levels: np.ndarray, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """(M, N, N') bool, M = log2 n_levels: plane m marks the pixels mask m etches (bit m of L − 1 − level)."""
    lv = validate_levels(levels, n_levels)
    return np.stack([bit_plane(lv, m, n_levels) for m in range(mask_count(n_levels))])


def bit_plane(levels: np.ndarray, bit: int, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """(N, N') bool: the pixels mask ``bit`` etches (bit ``bit`` of L − 1 − level); levels already validated."""
    return (((n_levels - 1) - np.asarray(levels, np.uint8)) >> bit & 1).astype(bool)


def levels_from_planes(planes: np.ndarray) -> np.ndarray:
    """Inverse of :func:`bit_planes` for M planes: level = 2^M − 1 − Σ 2^m·plane_m (uint8)."""
    etch = sum((planes[m].astype(np.int32) << m) for m in range(planes.shape[0]))
    return (((1 << planes.shape[0]) - 1) - etch).astype(np.uint8)


def plane_rectangles(plane: np.ndarray) -> np.ndarray:
    """Exact rectangle cover of a bool plane: (R, 4) int64 rows of (col0, row0, col1, row1), half-open.

    Each rectangle spans columns col0..col1-1 and rows row0..row1-1 of the array. Rectangles do not overlap.
    """
    plane = np.asarray(plane, dtype=bool)
    n, m = plane.shape
    padded = np.zeros((n, m + 2), np.int8)
    padded[:, 1:-1] = plane
    d = np.diff(padded, axis=1)
    r, s = np.nonzero(d == 1)
    _, e = np.nonzero(d == -1)  # row-major order pairs each start with its end
    if r.size == 0:
        return np.zeros((0, 4), np.int64)
    order = np.lexsort((r, e, s))
    r, s, e = r[order], s[order], e[order]
    brk = np.ones(r.size, bool)
    brk[1:] = (s[1:] != s[:-1]) | (e[1:] != e[:-1]) | (r[1:] != r[:-1] + 1)
    first = np.flatnonzero(brk)
    last = np.r_[first[1:], r.size] - 1
    return np.stack([s[first], r[first], e[first], r[last] + 1], axis=1).astype(np.int64)


def rasterize_rectangles(rects: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(N, M) int32 coverage count of half-open (col0, row0, col1, row1) rectangles."""
    n, m = shape
    r = np.asarray(rects, np.int64).reshape(-1, 4)
    c0, r0, c1, r1 = r[:, 0], r[:, 1], r[:, 2], r[:, 3]
    rows = np.concatenate([r0, r0, r1, r1])
    cols = np.concatenate([c0, c1, c0, c1])
    w = np.concatenate([np.ones_like(r0), -np.ones_like(r0), -np.ones_like(r0), np.ones_like(r0)])
    return _integrate(rows, cols, w, n, m)


def _integrate(rows, cols, weights, n, m) -> np.ndarray:
    """Scatter ±weights at (row, col) corners of an (n+1, m+1) grid and take the 2-D running sum (int32)."""
    acc = np.zeros((n + 1) * (m + 1), np.int32)
    np.add.at(acc, rows * (m + 1) + cols, np.asarray(weights, np.int32))
    acc = acc.reshape(n + 1, m + 1)
    np.cumsum(acc, axis=0, out=acc)
    np.cumsum(acc, axis=1, out=acc)
    return acc[:n, :m]


def rasterize_manhattan(points: np.ndarray, poly_index: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(N, M) winding number of Manhattan polygons given in pixel units (x = column, y = row, row 0 first).

    Args:
        points: (P, 2) integer vertices of all polygons, concatenated.
        poly_index: (P,) polygon id of each vertex (vertices of one polygon contiguous, in order).
    A vertical edge from row a to row b at column x adds ±1 to every pixel row in [min, max) right of x;
    summing over the edges gives the winding number (keyholes and holes come out right). Each polygon is
    first oriented positively (GDSII allows either orientation), so the result counts coverage.
    """
    n, m = shape
    pts = np.asarray(points, np.int64)
    idx = np.asarray(poly_index)
    nxt = np.arange(len(pts)) + 1
    ends = np.r_[idx[1:] != idx[:-1], True]
    starts = np.r_[True, idx[1:] != idx[:-1]]
    first_of = np.maximum.accumulate(np.where(starts, np.arange(len(pts)), 0))
    nxt[ends] = first_of[ends]
    x0, y0 = pts[:, 0], pts[:, 1]
    x1, y1 = pts[nxt, 0], pts[nxt, 1]
    # orientation of each polygon from its shoelace area; flip the negative ones
    cross = x0 * y1 - x1 * y0
    first = np.flatnonzero(starts)
    area2 = np.add.reduceat(cross, first) if len(first) else np.zeros(0, np.int64)
    orient = np.repeat(np.where(area2 >= 0, -1, 1), np.diff(np.r_[first, len(pts)]))
    vert = (x0 == x1) & (y0 != y1)
    if np.any((x0 != x1) & (y0 != y1)):
        raise DoefabError("non-Manhattan edge found in a polygon: etch layers must be axis-aligned")
    x, ya, yb = x0[vert], y0[vert], y1[vert]
    sign = np.where(yb > ya, 1, -1) * orient[vert]
    lo, hi = np.minimum(ya, yb), np.maximum(ya, yb)
    x = np.clip(x, 0, m)
    lo, hi = np.clip(lo, 0, n), np.clip(hi, 0, n)
    return _integrate(np.concatenate([lo, hi]), np.concatenate([x, x]), np.concatenate([sign, -sign]), n, m)
