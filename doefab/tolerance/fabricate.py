"""Fabricated relief from the mask layers, with each fabrication error applied where it happens.

Mask m (m = 0..M−1) etches ``2^m`` level steps where bit m of ``L − 1 − level`` is set (the bit planes the mask
export writes), so an overlay error moves exactly the pixels that mask moves and an etch error scales exactly
that mask's steps. Errors, in physical units:

The per-mask errors hold one entry per mask of the design (M = log2 L: 4 for 16 levels), or none for "nominal on
every mask" (:func:`per_mask`).

- ``depth_scale[m]``: etch depth of mask m relative to nominal (1.03 = 3 % too deep).
- ``overlay[m] = (dx, dy)`` metres and ``rotation[m]`` radians (about the DOE centre): where mask m lands
  relative to the design grid (the alignment chain is the caller's business: the judge composes it).
- ``edge_bias`` metres: every etched region grows (> 0) or shrinks (< 0) by this much per edge (critical
  dimension change of resist exposure and etch); ``corner_rounding`` metres: the radius of its rounded
  corners, applied as the bias that removes the same area (``relief.corner_bias``).
- ``roughness`` metres rms with correlation length ``roughness_corr`` metres: a Gaussian random surface with
  covariance rms²·exp(−r²/ℓ²), sampled as its mean over each cell (:func:`roughness_field`).

The exact areas of the heights in each cell come from :class:`doefab.tolerance.relief.ReliefModel`; this module
gives their mean height (for people and plots). The PSF judges use the cells' mean complex transmittance, which
is what a cell holding two heights sends into the far field.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from doefab.validate import length_m, wavelength_m
from doefab.validate import seed as seed_value
from doefab.errors import DoefabError
from doefab.fabrication.bitplanes import bit_planes
from doefab.fabrication.levels import material_level_step
from doefab.fabrication.process import DEFAULT_LEVELS, check_levels, mask_count
from doefab.io import read_json
from doefab.optics.camera import require_camera


__all__ = ["fabricated_height", "alignment_chain", "compose_overlay", "refined_camera", "level_step_for",
           "roughness_field", "check_errors", "per_mask", "MASK_NOMINAL"]

# each per-mask error's value on a mask made without that error
MASK_NOMINAL = {"depth_scale": 1.0, "overlay": (0.0, 0.0), "rotation": 0.0}


def level_step_for(camera, design_wavelength: float, n_levels: int = DEFAULT_LEVELS) -> float:
    """d = λ / (n(λ) − 1) / L (metres) of ``camera``'s material at ``design_wavelength``."""
    return material_level_step(camera.material, design_wavelength, n_levels)


def refined_camera(camera, supersample: int):
    """The camera whose DOE grid is ``supersample`` times finer (same extent): for the fabricated PSF."""
    return camera.replace(doe_pixels=camera.doe_pixels * supersample, doe_pitch=camera.doe_pitch / supersample)


def per_mask(name: str, value, n_masks: int) -> tuple:
    """Per-mask error ``name`` (a key of MASK_NOMINAL) with one entry per mask: empty (or None) means nominal on every
    mask; otherwise it must hold exactly ``n_masks`` entries (one error naming the design's mask count)."""
    if value is None:
        value = ()
    try:
        v = tuple(value)
    except TypeError:
        raise DoefabError(f"{name} needs one entry per mask ({n_masks}), got {value!r}") from None
    if not v:
        return (MASK_NOMINAL[name],) * n_masks
    if len(v) != n_masks:
        raise DoefabError(f"{name} needs one entry per mask: this design has {n_masks} mask{'s' * (n_masks != 1)} "
                          f"({1 << n_masks} levels), got {len(v)}")
    return v


def check_errors(depth_scale, overlay, rotation, edge_bias, roughness, corner_rounding, roughness_corr,
                 n_masks: int) -> tuple:
    """The fabrication errors as floats, each checked for type, finiteness and a plausible range in its unit
    (a value far outside is almost always a unit slip: metres and radians here)."""
    depth_scale, overlay, rotation = (per_mask(k, v, n_masks) for k, v in (("depth_scale", depth_scale),
                                                                           ("overlay", overlay), ("rotation", rotation)))
    try:
        scales = [float(v) for v in depth_scale]
        shifts = [tuple(float(a) for a in v) for v in overlay]
        rots = [float(v) for v in rotation]
        bias, rough, corner, corr = float(edge_bias), float(roughness), float(corner_rounding), float(roughness_corr)
    except (TypeError, ValueError):
        raise DoefabError("fabrication errors must be numbers (metres, radians, relative depths)") from None
    if any(len(s) != 2 for s in shifts):
        raise DoefabError("each overlay entry is (dx, dy) in metres")
    if any(not math.isfinite(v) or not 0 < v < 2 for v in scales):
        raise DoefabError(f"depth_scale entries are relative depths in (0, 2), got {scales}")
    for name, v, lim in (("overlay", max((abs(a) for s in shifts for a in s), default=0), 2e-3),
                         ("rotation", max(map(abs, rots)), 0.1), ("edge_bias", abs(bias), 1e-5),
                         ("corner_rounding", abs(corner), 1e-5), ("roughness", abs(rough), 1e-6)):
        if not math.isfinite(v) or v > lim:
            raise DoefabError(f"{name} {v:g} is outside ±{lim:g} (metres or radians): check the unit")
    if rough < 0 or corner < 0:
        raise DoefabError("roughness and corner_rounding are ≥ 0")
    if not (math.isfinite(corr) and 1e-8 <= corr <= 1e-3):
        raise DoefabError(f"roughness_corr {corr:g} m is outside 10 nm – 1 mm: check the unit (metres)")
    return scales, shifts, rots, bias, rough, corner, corr


def roughness_field(shape: tuple, cell: float, rms: float, corr: float, seed: int) -> tuple[np.ndarray, float]:
    """(field, residual rms): a Gaussian surface (covariance rms²·exp(−r²/ℓ²)) as its mean over each cell of
    side ``cell`` (metres), and the rms of what the cell means leave out (the unresolved part, which scatters
    light out of the window: a loss exp(−(kΔn·residual)²/2) of the field's amplitude)."""
    from scipy import ndimage

    if rms <= 0:
        return np.zeros(shape), 0.0
    u = cell / corr
    g = math.sqrt(math.pi) * math.erf(u) / u - (1 - math.exp(-u * u)) / (u * u)  # variance kept per axis
    kept = rms * g  # both axes: rms · g
    noise = np.random.default_rng(seed).normal(size=shape)
    field = ndimage.gaussian_filter(noise, corr / cell / math.sqrt(2), mode="wrap")
    field *= kept / max(field.std(), 1e-30)
    return field, rms * math.sqrt(max(1 - g * g, 0.0))


def fabricated_height(levels, camera, design_wavelength: float | None = None, depth_scale=(), overlay=(),
                      rotation=(), edge_bias: float = 0.0, roughness: float = 0.0, supersample: int = 4, seed: int = 0,
                      corner_rounding: float = 0.0, roughness_corr: float = 2e-6,
                      n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """Mean height (metres) of each cell of the fabricated DOE on the design grid refined ``supersample`` times.

    Args:
        levels: (N, N) integer levels 0..L−1 (the design's level map, row 0 at the top, x < 0 coded).
        camera: the design camera (its pitch and material).
        design_wavelength: metres; sets the level step d = λ / (n(λ) − 1) / L (None: the camera's own, as
            ``levels_to_height`` and the mask export take it).
        depth_scale, overlay (metres), rotation (radians): one entry per mask (M = log2 L), or empty for none;
        edge_bias, roughness, corner_rounding, roughness_corr (metres): see the module docstring.
        supersample: cells per DOE pixel and axis (1–16).  seed: seeds the roughness.
        n_levels: L, the design's levels (2, 4, 8, 16 or 32; ``Design.n_levels``).
    Returns:
        (N·s, N·s) float64 heights; with no error, each DOE pixel's height repeated s × s times.

    Example:

        >>> import numpy as np, doefab
        >>> cam = doefab.Camera(doe_pixels=64, doe_pitch=135e-6)
        >>> levels = np.zeros((64, 64), np.uint8); levels[:, :32] = 8
        >>> h = doefab.fabricated_height(levels, cam)  # no error: each pixel's level × d, on a 4× finer grid
        >>> h.shape, (np.unique(h) * 1e9).round(2).tolist()  # nm
        ((256, 256), [0.0, 597.94])
    """
    from doefab.tolerance.relief import MaskErrors, ReliefModel, corner_bias, mean_height, pattern_heights

    camera = require_camera(camera)
    design_wavelength = wavelength_m("design_wavelength", camera.design_wavelength if design_wavelength is None
                                     else design_wavelength)
    roughness_corr, seed = length_m("roughness_corr", roughness_corr, 1e-9, 1e-2), seed_value("seed", seed)
    lv = np.asarray(levels)
    if lv.ndim != 2 or lv.shape[0] != lv.shape[1] or lv.shape[0] != camera.doe_pixels:
        raise DoefabError(f"levels must be ({camera.doe_pixels}, {camera.doe_pixels}) on the camera's grid, got "
                          f"{lv.shape}")
    n_levels = check_levels(n_levels, "n_levels")
    if lv.dtype.kind not in "iu" or lv.min() < 0 or lv.max() >= n_levels:
        raise DoefabError(f"levels must be integers 0..{n_levels - 1} (n_levels = {n_levels})")
    if not isinstance(supersample, int) or not 1 <= supersample <= 16:
        raise DoefabError(f"supersample must be an integer 1..16, got {supersample!r}")
    n_masks = mask_count(n_levels)
    scales, shifts, rots, bias, rough, corner, corr = check_errors(depth_scale, overlay, rotation, edge_bias,
                                                                   roughness, corner_rounding, roughness_corr, n_masks)
    planes = bit_planes(lv, n_levels)
    model = ReliefModel(planes, camera.doe_pitch, supersample)
    pitch = camera.doe_pitch
    biases = tuple(bias + corner_bias(p, corner / pitch) * pitch for p in planes)
    hist = model.histogram(MaskErrors(tuple(shifts), tuple(rots), biases))
    d = level_step_for(camera, design_wavelength, n_levels)
    h = mean_height(hist, pattern_heights(n_masks, d, scales)).numpy().reshape(model.n, model.n)
    if rough > 0:
        h = h + roughness_field(h.shape, model.cell, rough, corr, seed)[0]
    return h


def alignment_chain(design_dir: Path | None, n_masks: int) -> dict:
    """``{plate: plate it aligns to}`` from the mask set's manifest beside ``design_dir`` (a mask set's
    ``design/``) or in a run's ``masks/`` beside it (chrome = 0); without one, every one of the ``n_masks`` etch
    plates aligns to the chrome plate."""
    man = None
    if design_dir is not None:
        man = Path(design_dir).parent / "manifest.json"
        if not man.is_file():
            man = Path(design_dir).parent / "masks" / "manifest.json"
    if man is not None and man.is_file():
        try:
            return {int(k): int(v) for k, v in read_json(man)["alignment_chain"].items()}
        except (KeyError, ValueError, TypeError):
            pass
    return {m + 1: 0 for m in range(n_masks)}


def compose_overlay(err, chain: dict, n_masks: int) -> tuple[list, list]:
    """Where each of the ``n_masks`` masks of a part (``PartErrors``) landed on the die: its own error relative to
    the plate it aligns to, accumulated along the alignment chain (the chrome layer, plate 0, is the die's frame).
    Mounting errors are not here: they move the die, not the masks on it."""
    err = err.for_masks(n_masks)
    shifts, rots = [], []
    for m in range(n_masks):
        plate, dx, dy, th = m + 1, 0.0, 0.0, 0.0
        seen = set()
        while plate != 0 and plate not in seen:
            seen.add(plate)
            k = plate - 1
            dx, dy, th = dx + err.overlay[k][0], dy + err.overlay[k][1], th + err.rotation[k]
            plate = chain.get(plate, 0)
        shifts.append((dx, dy))
        rots.append(th)
    return shifts, rots
