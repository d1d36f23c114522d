"""Fabricated heights from the mask layers, with each fabrication error applied where it happens.

Mask m (m = 0..3) etches ``2^m`` level steps where bit m of ``15 − level`` is set (the same bit planes the mask
export writes). The fabricated relief is ``h = 15·d − Σ_m s_m · 2^m·d · E_m(x, y)`` with ``E_m`` the etched
fraction of mask m at each point and ``s_m`` its etch-depth scale, so an overlay error moves exactly the pixels
that mask moves and an etch error scales exactly that mask's steps. Errors, in physical units:

- ``depth_scale[m]``: etch depth of mask m relative to nominal (1.03 = 3 % too deep).
- ``overlay[m] = (dx, dy)`` metres and ``rotation[m]`` radians (about the DOE centre): where mask m lands
  relative to the design grid (the alignment chain is the caller's business: ``sample_errors`` composes it).
- ``edge_bias`` metres: every etched region grows (> 0) or shrinks (< 0) by this much per edge (critical
  dimension change of resist exposure and etch); ``corner_rounding`` metres: radius of the rounded corners.
- ``roughness`` metres rms with correlation length ``roughness_corr`` metres: a Gaussian random surface.

The result is sampled on the design grid refined ``supersample`` times: each fine pixel holds the height
averaged over its area (masks are rasterised by exact area for shifts; edge bias and corner rounding by a
signed-distance ramp one fine pixel wide), so sub-pixel errors are not rounded away. With no perturbation it
reproduces ``levels_to_height`` exactly (each DOE pixel repeated ``supersample²`` times).
"""

from __future__ import annotations

import math

import numpy as np

from doefab._validate import length_m, wavelength_m
from doefab._validate import seed as seed_value
from doefab.errors import DoefabError
from doefab.fabrication.bitplanes import N_MASKS, bit_plane
from doefab.fabrication.levels import N_LEVELS

__all__ = ["fabricated_height", "refined_camera", "level_step_for"]


def level_step_for(camera, design_wavelength: float) -> float:
    """d = λ / (n(λ) − 1) / 16 (metres)."""
    return float(design_wavelength / (camera.material.index(design_wavelength) - 1.0) / N_LEVELS)


def refined_camera(camera, supersample: int):
    """The camera whose DOE grid is ``supersample`` times finer (same extent): for the fabricated PSF."""
    return camera.replace(doe_pixels=camera.doe_pixels * supersample, doe_pitch=camera.doe_pitch / supersample)


def _tuple4(name, value):
    v = tuple(value)
    if len(v) != N_MASKS:
        raise DoefabError(f"{name} needs one entry per mask ({N_MASKS}), got {len(v)}")
    return v


def _etched_fraction(plane: np.ndarray, s: int, pitch_f: float, shift, theta: float, bias: float,
                     rounding: float) -> np.ndarray:
    """Fraction (0..1) of each fine pixel etched by one mask, after bias, rounding, shift and rotation."""
    from scipy import ndimage

    fine = np.kron(plane.astype(np.float64), np.ones((s, s)))
    if bias != 0.0 or rounding > 0.0:
        b = plane.astype(bool)
        binf = np.kron(b, np.ones((s, s), bool))
        d_out = ndimage.distance_transform_edt(~binf) * pitch_f  # distance of outside points to the etched region
        d_in = ndimage.distance_transform_edt(binf) * pitch_f
        sd = np.where(binf, d_in - 0.5 * pitch_f, -(d_out - 0.5 * pitch_f))  # > 0 inside, edge at 0
        if rounding > 0.0:
            sd = ndimage.gaussian_filter(sd, rounding / pitch_f / 2.0, mode="nearest")
        fine = np.clip(0.5 + (sd + bias) / pitch_f, 0.0, 1.0)
    dx, dy = shift
    if dx == 0.0 and dy == 0.0 and theta == 0.0:
        return fine
    n = fine.shape[0]
    c = (n - 1) / 2.0
    rows, cols = np.mgrid[:n, :n].astype(np.float64)
    x, y = (cols - c) * pitch_f, (c - rows) * pitch_f  # metres, y up
    ct, st = math.cos(theta), math.sin(theta)
    xs, ys = x - dx, y - dy  # undo the shift, then the rotation, to find where this point was on the mask
    x0, y0 = ct * xs + st * ys, -st * xs + ct * ys
    coords = np.stack([c - y0 / pitch_f, x0 / pitch_f + c])
    return ndimage.map_coordinates(fine, coords, order=1, mode="constant", cval=0.0)


def fabricated_height(levels, camera, design_wavelength: float = 550e-9, depth_scale=(1.0,) * N_MASKS,
                      overlay=((0.0, 0.0),) * N_MASKS, rotation=(0.0,) * N_MASKS, edge_bias: float = 0.0,
                      roughness: float = 0.0, supersample: int = 4, seed: int = 0, corner_rounding: float = 0.0,
                      roughness_corr: float = 2e-6) -> np.ndarray:
    """Heights (metres) of the fabricated DOE on the design grid refined ``supersample`` times (see module doc).

    Args:
        levels: (N, N) integer levels 0..15 (the design's level map, row 0 at the top, x < 0 coded).
        camera: the design camera (its pitch and material).
        design_wavelength: metres; sets the level step d = λ / (n(λ) − 1) / 16.
    """
    design_wavelength = wavelength_m("design_wavelength", design_wavelength)
    roughness_corr, seed = length_m("roughness_corr", roughness_corr, 1e-9, 1e-2), seed_value("seed", seed)
    lv = np.asarray(levels)
    if lv.ndim != 2 or lv.shape[0] != lv.shape[1] or lv.shape[0] != camera.doe_pixels:
        raise DoefabError(f"levels must be ({camera.doe_pixels}, {camera.doe_pixels}) on the camera's grid, got "
                          f"{lv.shape}")
    if lv.dtype.kind not in "iu" or lv.min() < 0 or lv.max() >= N_LEVELS:
        raise DoefabError("levels must be integers 0..15")
    if not isinstance(supersample, int) or not 1 <= supersample <= 16:
        raise DoefabError(f"supersample must be an integer 1..16, got {supersample!r}")
    scales = [float(v) for v in _tuple4("depth_scale", depth_scale)]
    if any(not math.isfinite(v) or not 0 < v < 2 for v in scales):
        raise DoefabError(f"depth_scale entries are relative depths in (0, 2), got {scales}")
    shifts = [tuple(float(a) for a in v) for v in _tuple4("overlay", overlay)]
    rots = [float(v) for v in _tuple4("rotation", rotation)]
    for name, v, lim in (("overlay", max((abs(a) for s in shifts for a in s), default=0), 2e-3),
                         ("rotation", max(map(abs, rots)), 0.1), ("edge_bias", abs(edge_bias), 1e-5),
                         ("corner_rounding", abs(corner_rounding), 1e-5), ("roughness", abs(roughness), 1e-6)):
        if not math.isfinite(v) or v > lim:
            raise DoefabError(f"{name} {v:g} is outside ±{lim:g} (metres or radians): check the unit")
    if roughness < 0 or corner_rounding < 0:
        raise DoefabError("roughness and corner_rounding are ≥ 0")
    s = supersample
    d = level_step_for(camera, design_wavelength)
    pitch_f = camera.doe_pitch / s
    h = np.full((lv.shape[0] * s,) * 2, (N_LEVELS - 1) * d)
    for m in range(N_MASKS):
        plane = bit_plane(lv.astype(np.uint8), m)
        if not plane.any():
            continue
        frac = _etched_fraction(plane, s, pitch_f, shifts[m], rots[m], float(edge_bias), float(corner_rounding))
        h -= scales[m] * (1 << m) * d * frac
    if roughness > 0:
        from scipy import ndimage

        rng = np.random.default_rng(seed)
        noise = ndimage.gaussian_filter(rng.normal(size=h.shape), max(roughness_corr / pitch_f, 0.5) / math.sqrt(2),
                                        mode="wrap")
        h += roughness * noise / max(noise.std(), 1e-30)
    return h
