"""Depth layouts with the geometry of rooms and streets, for training only.

``data.depth_sample``'s layered scenes put the background at the far end of the range and every object
fronto-parallel at a depth drawn evenly in metres, so a depth-from-defocus network sees few surfaces near the
camera (where the blur, and so the cue, is largest) and none that are slanted or curved. ``world_layout`` adds
what measured depth maps hold:

- a background plane at any depth of the range, slanted: inverse depth linear across the image, as any plane
  projects through a pinhole (a wall seen at an angle, a floor, a table top);
- objects at depths drawn evenly in inverse depth (evenly in the defocus blur, which is linear in 1/z), each
  fronto-parallel, slanted, or curved toward the camera (a dome that follows the object's outline, from its
  distance transform);
- depth edges where the texture changes (each surface its own texture), occlusion far to near.

Only the training split draws these (``data.depth_sample`` with split "train"); the validation, test and final
scenes are unchanged, so the networks trained with and without them are compared on the same scenes.
"""

from __future__ import annotations

import numpy as np

__all__ = ["WORLD_SHARE", "world_layout", "shape_mask"]

WORLD_SHARE = 0.5  # the share of training depth scenes drawn by ``world_layout``
MAX_TILT = 0.6  # a slanted surface's inverse depth changes by up to this share of the range's across the image
MAX_DOME = 0.25  # a curved object's centre comes nearer by up to this share of the range's inverse depth


def world_layout(rng: np.random.Generator, size: int, near: float, far: float, texture_of) -> tuple:
    """(scene [3, S, S] radiance, depth [S, S] metres within ``near``–``far``): a slanted background plane and 2–6
    occluding objects (flat, slanted or curved), each surface textured by ``texture_of(rng)`` ([3, S, S] in
    [0, 1]); depths in metres, radiance up to about 2 (a half-exposure capture reaches about 1).

    Example: ``world_layout(np.random.default_rng(0), 64, 1.0, 5.0, lambda r: r.random((3, 64, 64)))`` gives a
    64² scene and its depth map between 1 and 5 m."""
    lo, hi = 1.0 / far, 1.0 / near  # inverse depth, 1/m
    span = hi - lo
    yy, xx = np.mgrid[:size, :size] / max(size - 1, 1) - 0.5
    gain = rng.uniform(0.8, 1.8)
    inv = _plane(rng, xx, yy, rng.uniform(lo, lo + 0.6 * span), span, lo, hi)
    scene = texture_of(rng) * gain
    for z_inv in np.sort(rng.uniform(lo, hi, int(rng.integers(2, 7)))):  # far to near
        m = shape_mask(rng, size)
        kind = rng.integers(3)
        if kind == 0:
            surface = np.full((size, size), z_inv)
        elif kind == 1:
            surface = _plane(rng, xx, yy, z_inv, 0.5 * span, lo, hi)
        else:
            surface = np.clip(z_inv + _dome(m) * rng.uniform(0, MAX_DOME) * span, lo, hi)
        m &= surface >= inv  # in front of what is there only
        inv = np.where(m, surface, inv)
        scene = np.where(m[None], texture_of(rng) * gain * rng.uniform(0.5, 1.0), scene)
    return scene.astype(np.float32), (1.0 / inv).astype(np.float32)


def _plane(rng, xx, yy, centre: float, span: float, lo: float, hi: float) -> np.ndarray:
    """Inverse depth of a plane through ``centre`` at the image's middle, tilted by up to ``MAX_TILT`` of
    ``span`` across the image, clipped to [lo, hi]."""
    gx, gy = rng.uniform(-MAX_TILT, MAX_TILT, 2) * span
    return np.clip(centre + gx * xx + gy * yy, lo, hi)


def _dome(mask: np.ndarray) -> np.ndarray:
    """0 at a mask's outline rising to 1 at its innermost pixel, round (a square root of the distance inward)."""
    from scipy.ndimage import distance_transform_edt

    if not mask.any():
        return np.zeros(mask.shape)
    d = distance_transform_edt(mask)
    return np.sqrt(d / d.max())


def shape_mask(rng: np.random.Generator, size: int) -> np.ndarray:
    """[S, S] bool: an ellipse, a rectangle or a rotated bar of random place and size (8–40 % of the side)."""
    yy, xx = np.mgrid[:size, :size]
    cy, cx = rng.uniform(0, size, 2)
    ry, rx = rng.uniform(0.08, 0.4, 2) * size
    kind = rng.integers(3)
    if kind == 0:
        return ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1
    if kind == 1:
        return (np.abs(yy - cy) <= ry) & (np.abs(xx - cx) <= rx)
    a = rng.uniform(0, np.pi)
    u = (xx - cx) * np.cos(a) + (yy - cy) * np.sin(a)
    v = -(xx - cx) * np.sin(a) + (yy - cy) * np.cos(a)
    return (np.abs(u) <= rx) & (np.abs(v) <= ry * 0.5)
