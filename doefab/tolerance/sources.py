"""The sources of error a tolerance budget describes, one row each (``SOURCES``): the budget keys it reads
(section, name with its unit, plausible range), what every part carries of it, how a part's value is drawn, and
the surrogate's parameters for it. The budget's key table (``errors.BUDGET_KEYS``), the draws
(``errors.sample_errors``), the surrogate's base part and parameters (``surrogate``) and the judged kinds
(``kinds.KINDS``, each naming its source) are read from this table, so a new source of error is one row here
(and, for its physics, the module that applies its ``PartErrors`` field: ``fabricate``/``relief`` for the masks,
``mounted`` for the mount, ``doefab.imaging.crosstalk`` for the sensor).

Draws are made in the table's order from one generator, so the order of the rows is part of the contract: the same
seed gives the same parts, bit for bit.

Example::

    >>> from doefab.tolerance.sources import source
    >>> [k.key for k in source("etch depth").keys]
    ['systematic_sigma_percent', 'random_sigma_percent']
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import partial
from typing import Callable, NamedTuple

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E

__all__ = ["BudgetKey", "Param", "Source", "SOURCES", "source", "budget_keys", "whole_keys", "fixed_fields",
           "drawn_fields", "surrogate_params", "apply_psf_effects", "chain_depth", "budget_value", "nominal_gap",
           "sensor_errors", "tilt_phase_factor", "etch_sigma"]


@dataclass(frozen=True)
class BudgetKey:
    """A budget key: ``key`` (its unit in its name) in section ``section``, a number within [lo, hi] (both None:
    true or false); ``whole``: it counts something (a whole number only)."""

    section: str
    key: str
    lo: float | None = None
    hi: float | None = None
    whole: bool = False


class Param(NamedTuple):
    """One surrogate parameter x_j: its name, its step h (SI), ``set(part, x)`` the part with it at x, ``get(part)``
    its value on a part (the overlay composed along the alignment chain), ``uniform``: drawn uniformly within ±h
    (judged at ±h/2 besides ±h; a normal error also at ±3h/2)."""

    name: str
    h: float
    set: Callable
    get: Callable
    uniform: bool = False


@dataclass(frozen=True)
class Source:
    """One source of error: ``keys`` it reads; ``fixed(budget)`` the ``PartErrors`` fields every part carries of
    it; ``draw(budget, rng, n_masks)`` the fields of one drawn part (None: nothing is drawn); ``params(budget, chain,
    n_masks, gap)`` its surrogate parameters (the zero-σ ones left out); ``psf(psfs, part)`` its effect on a part's
    PSFs ({half: [depths, wavelengths, K, K]}) where it acts after them (None: its physics acts on the pupil, in the
    module that builds it)."""

    name: str
    keys: tuple
    fixed: Callable[[dict], dict] | None = None
    draw: Callable[[dict, np.random.Generator, int], dict] | None = None
    params: Callable[[dict, dict, int, bool], list] | None = None
    psf: Callable[[dict, object], dict] | None = None


def budget_value(budget: dict, sec: str, key: str, default: float = 0.0) -> float:
    """``budget[sec][key]`` as a float (``default`` when absent)."""
    return float(budget.get(sec, {}).get(key, default))


_v = budget_value


def chain_depth(chain: dict, m: int) -> int:
    """How many plates' overlay errors add up on mask m (its path to the chrome plate in the alignment chain)."""
    plate, depth, seen = m + 1, 0, set()
    while plate != 0 and plate not in seen:
        seen.add(plate)
        depth += 1
        plate = chain.get(plate, 0)
    return max(depth, 1)


def _per_mask(name: str, m: int, base: float = 0.0, axis: int | None = None):
    """(set, get) of entry m (its ``axis`` component) of the per-mask field ``name``, offset by ``base``."""
    def set_(part, x):
        v = list(getattr(part, name))
        if axis is None:
            v[m] = base + x
        else:
            xy = list(v[m])
            xy[axis] = x
            v[m] = tuple(xy)
        return replace(part, **{name: tuple(v)})

    def get(part):
        v = getattr(part, name)[m]
        return (v - base) if axis is None else v[axis]
    return set_, get


def _scalar(name: str, axis: int | None = None):
    """(set, get) of the field ``name`` (its ``axis`` component)."""
    def set_(part, x):
        if axis is None:
            return replace(part, **{name: x})
        v = list(getattr(part, name))
        v[axis] = x
        return replace(part, **{name: tuple(v)})
    return set_, (lambda part: getattr(part, name) if axis is None else getattr(part, name)[axis])


# ---- etch depth: a systematic part shared by a die's plates and a random part per plate ----------------------
def etch_sigma(b: dict) -> float:
    """One standard deviation of a plate's etch depth (fraction): the systematic and random parts in quadrature."""
    return math.hypot(_v(b, "etch", "systematic_sigma_percent"), _v(b, "etch", "random_sigma_percent")) / 100


def _etch_draw(b, rng, m):
    sys_ = rng.normal(0, _v(b, "etch", "systematic_sigma_percent") / 100)
    rnd = rng.normal(0, _v(b, "etch", "random_sigma_percent") / 100, m)
    return {"depth_scale": tuple(float(np.clip(1 + sys_ + r, 0.5, 1.5)) for r in rnd)}


def _etch_params(b, chain, n, gap):
    s = etch_sigma(b)
    return [Param(f"etch depth, mask {m + 1}", 2 * s, *_per_mask("depth_scale", m, 1.0)) for m in range(n if s else 0)]


# ---- mask overlay and rotation: per plate, composed along the alignment chain ---------------------------------
def _shift_draw(b, rng, m):
    sig = _v(b, "overlay", "shift_sigma_um") * 1e-6
    return {"overlay": tuple((float(a), float(c)) for a, c in rng.normal(0, sig, (m, 2))) if sig > 0
            else ((0.0, 0.0),) * m}


def _shift_params(b, chain, n, gap):
    s = _v(b, "overlay", "shift_sigma_um") * 1e-6
    out = []
    for m in range(n if s > 0 else 0):
        h = 2 * s * math.sqrt(chain_depth(chain, m))
        out += [Param(f"overlay {ax}, mask {m + 1}", h, *_per_mask("overlay", m, axis=i)) for i, ax in enumerate("xy")]
    return out


def _rotation_draw(b, rng, m):
    return {"rotation": tuple(float(v) for v in rng.normal(0, _v(b, "overlay", "rotation_sigma_urad") * 1e-6, m))}


def _rotation_params(b, chain, n, gap):
    s = _v(b, "overlay", "rotation_sigma_urad") * 1e-6
    return [Param(f"mask rotation, mask {m + 1}", 2 * s * math.sqrt(chain_depth(chain, m)), *_per_mask("rotation", m))
            for m in range(n if s > 0 else 0)]


# ---- lithography and surface ------------------------------------------------------------------------------------
def _bias_params(b, chain, n, gap):
    s = _v(b, "lithography", "edge_bias_sigma_um")
    return [Param("edge bias", 2e-6 * s, *_scalar("edge_bias"))] if s > 0 else []


# ---- mounting ---------------------------------------------------------------------------------------------------
def nominal_gap(budget: dict) -> float:
    """Nominal DOE-to-aperture-plane distance (metres): the holder's DOE-to-glass distance plus the depth of the
    lens's entrance pupil behind its front glass."""
    return (_v(budget, "mounting", "axial_gap_mm") + _v(budget, "mounting", "pupil_behind_glass_mm")) * 1e-3


def _decenter_draw(b, rng, m):
    d = _v(b, "mounting", "decenter_max_mm") * 1e-3
    return {"mount_shift": tuple(float(v) for v in rng.uniform(-d, d, 2))}


def _decenter_params(b, chain, n, gap):
    d = _v(b, "mounting", "decenter_max_mm") * 1e-3
    return [Param(f"decenter {w} split", d, *_scalar("mount_shift", i), uniform=True)
            for i, w in enumerate(("across", "along"))] if d > 0 else []


def _mount_rotation_params(b, chain, n, gap):
    s = _v(b, "mounting", "rotation_sigma_deg")
    return [Param("mount rotation", 2 * math.radians(s), *_scalar("mount_rotation"))] if s > 0 else []


def _gap_draw(b, rng, m):
    return {"axial_gap": max(0.0, nominal_gap(b) + float(rng.normal(0, _v(b, "mounting", "axial_gap_sigma_mm")
                                                                     * 1e-3)))}


def _gap_params(b, chain, n, gap):
    s = _v(b, "mounting", "axial_gap_sigma_mm")
    if not gap or s <= 0:
        return []
    g0 = nominal_gap(b)
    return [Param("axial gap", 2e-3 * s, lambda part, x: replace(part, axial_gap=max(0.0, g0 + x)),
                  lambda part: part.axial_gap - g0)]


# ---- mount tilt: the die's normal off the optical axis ---------------------------------------------------------
def tilt_phase_factor(theta: float, n: float) -> float:
    """The relief's optical path difference at incidence ``theta`` (radians) over the one at normal incidence, for
    a relief of index ``n`` in air: (√(n² − sin²θ) − cos θ) / (n − 1), 1 + θ²/(2n) to second order (a step
    of height h delays a ray that crosses it at θ by h·(n·cos θ_t − cos θ), θ_t its angle inside the glass).

    Example: ``tilt_phase_factor(math.radians(1), 1.46)`` → 1.000104 (a 1° tilt deepens the relief by 0.01 %)."""
    s = math.sin(theta)
    return (math.sqrt(n * n - s * s) - math.cos(theta)) / (n - 1)


def _tilt_params(b, chain, n, gap):
    s = _v(b, "mounting", "tilt_sigma_deg")
    return [Param("mount tilt", 2 * math.radians(s), *_scalar("mount_tilt"))] if s > 0 else []


def sensor_errors(budget: dict) -> dict:
    """The ``PartErrors`` fields of the budget's ``[sensor]`` section (dual-pixel crosstalk and its calibration; the
    sensor's noise where a scene's ``[sensor]`` put it there, the default sensor's otherwise)."""
    g = partial(budget_value, budget, "sensor")
    return {"crosstalk": (g("crosstalk_lr_percent") / 100, g("crosstalk_rl_percent") / 100),
            "crosstalk_slope": g("crosstalk_slope_percent") / 100,
            "calibrated": bool(budget.get("sensor", {}).get("calibrated", True)),
            "calibration_rows": int(g("calibration_rows", 3072)), "calibration_level": g("calibration_level", 0.5),
            "calibrated_width_px": int(g("calibrated_width_px", 3072)),
            "full_well_e": g("full_well_e", DEFAULT_FULL_WELL_E),
            "read_noise_e": g("read_noise_e", DEFAULT_READ_NOISE_E)}


def _keys(section: str, *rows) -> tuple:
    return tuple(BudgetKey(section, *r) for r in rows)


SOURCES = (
    Source("etch depth", _keys("etch", ("systematic_sigma_percent", 0, 50), ("random_sigma_percent", 0, 50)),
           draw=_etch_draw, params=_etch_params),
    Source("mask overlay", _keys("overlay", ("shift_sigma_um", 0, 20)), draw=_shift_draw, params=_shift_params),
    Source("mask rotation", _keys("overlay", ("rotation_sigma_urad", 0, 5000)), draw=_rotation_draw,
           params=_rotation_params),
    Source("edge bias", _keys("lithography", ("edge_bias_sigma_um", 0, 5)),
           draw=lambda b, rng, m: {"edge_bias": float(rng.normal(0, _v(b, "lithography", "edge_bias_sigma_um")
                                                                    * 1e-6))}, params=_bias_params),
    Source("corner rounding", _keys("lithography", ("corner_rounding_um", 0, 5)),
           fixed=lambda b: {"corner_rounding": _v(b, "lithography", "corner_rounding_um") * 1e-6}),
    Source("surface roughness", _keys("surface", ("roughness_rms_nm", 0, 200), ("correlation_length_um", 0.1, 1000)),
           fixed=lambda b: {"roughness": _v(b, "surface", "roughness_rms_nm") * 1e-9,
                            "roughness_corr": _v(b, "surface", "correlation_length_um", 2.0) * 1e-6}),
    Source("decenter", _keys("mounting", ("decenter_max_mm", 0, 5)), draw=_decenter_draw, params=_decenter_params),
    Source("mount rotation", _keys("mounting", ("rotation_sigma_deg", 0, 30)),
           draw=lambda b, rng, m: {"mount_rotation": float(rng.normal(0, math.radians(
               _v(b, "mounting", "rotation_sigma_deg"))))}, params=_mount_rotation_params),
    Source("axial gap", _keys("mounting", ("axial_gap_mm", 0, 50), ("axial_gap_sigma_mm", 0, 10),
                              ("pupil_behind_glass_mm", 0, 45)),
           fixed=lambda b: {"axial_gap": nominal_gap(b)}, draw=_gap_draw, params=_gap_params),
    Source("mount tilt", _keys("mounting", ("tilt_sigma_deg", 0, 10)),
           draw=lambda b, rng, m: {"mount_tilt": float(rng.normal(0, math.radians(
               _v(b, "mounting", "tilt_sigma_deg"))))}, params=_tilt_params),
    Source("sensor crosstalk", _keys("sensor", ("crosstalk_lr_percent", 0, 49.9), ("crosstalk_rl_percent", 0, 49.9),
                                     ("crosstalk_slope_percent", 0, 20), ("calibrated",),
                                     ("calibration_rows", 1, 100000, True), ("calibration_level", 0.01, 1),
                                     ("calibrated_width_px", 16, 100000, True)), fixed=sensor_errors),
)


def source(name: str, sources: tuple | None = None) -> Source:
    """The source of error called ``name``; a DoefabError naming the choices for any other."""
    sources = SOURCES if sources is None else sources
    for s in sources:
        if s.name == name:
            return s
    raise DoefabError(f"unknown source of error {name!r}: choose one of {', '.join(s.name for s in sources)}")


def budget_keys(sources: tuple | None = None) -> dict:
    """{section: {key: (lo, hi), or None for true/false}} of every source's keys, in the table's order, and the
    ``spec`` section (per-task tables, checked by ``doefab.tolerance.spec``)."""
    out: dict = {}
    for s in SOURCES if sources is None else sources:
        for k in s.keys:
            out.setdefault(k.section, {})[k.key] = None if k.lo is None else (k.lo, k.hi)
    return {**out, "spec": None}


def whole_keys(sources: tuple | None = None) -> set:
    """{(section, key)} of the keys that count something (whole numbers only)."""
    return {(k.section, k.key) for s in (SOURCES if sources is None else sources) for k in s.keys if k.whole}


def fixed_fields(budget: dict, sources: tuple | None = None) -> dict:
    """The ``PartErrors`` fields every part of ``budget`` carries (no draw): the surrogate's base part."""
    out: dict = {}
    for s in SOURCES if sources is None else sources:
        if s.fixed is not None:
            out.update(s.fixed(budget))
    return out


def drawn_fields(budget: dict, rng: np.random.Generator, n_masks: int, sources: tuple | None = None) -> dict:
    """The ``PartErrors`` fields of one part drawn with ``rng``: every source's fixed fields, then its draws, in the
    table's order."""
    out = fixed_fields(budget, sources)
    for s in SOURCES if sources is None else sources:
        if s.draw is not None:
            out.update(s.draw(budget, rng, n_masks))
    return out


def surrogate_params(budget: dict, chain: dict, n_masks: int, gap: bool = False, sources: tuple | None = None) -> list:
    """[Param] of every source, in the table's order (``surrogate.parameters``)."""
    return [p for s in (SOURCES if sources is None else sources) if s.params is not None
            for p in s.params(budget, chain, n_masks, gap)]


def apply_psf_effects(psfs: dict, part, sources: tuple | None = None) -> dict:
    """``psfs`` ({half: PSF}) of ``part`` with every source's PSF-level effect applied, in the table's order (the
    sources whose physics acts on the pupil apply it where the pupil is built: ``relief``, ``mounted``)."""
    for s in SOURCES if sources is None else sources:
        if s.psf is not None:
            psfs = s.psf(psfs, part)
    return psfs
