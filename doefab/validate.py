"""Small input checks shared by the public API (one clear error per problem, naming the argument, its unit and
the fix; a length typed in the wrong unit gets the conversion: "550 nm is 5.5e-07 m")."""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from doefab.errors import DoefabError


def is_half(x) -> bool:
    """Whether ``x`` (a numpy or torch array or scalar) holds half-precision floats (float16, bfloat16)."""
    return str(getattr(x, "dtype", "")).removeprefix("torch.") in ("float16", "bfloat16")


def full_precision(name: str, values, unit: str = "metres") -> None:
    """Refuse half-precision floats — an array, a tensor, or a list holding such scalars: float16 keeps 11
    significant bits and has no normal number below 6.1e-5, so lengths in metres arrive already rounded (a
    wavelength of 550e-9 m is stored as 5.36e-07 m) and heights of ~1e-7 m become subnormal."""
    if is_half(values) or (isinstance(values, (list, tuple)) and any(is_half(v) for v in values)):
        raise DoefabError(f"{name} is half precision ({getattr(values, 'dtype', 'float16')}), which rounds values "
                          f"in {unit} (550e-9 is stored as {float(np.float16(550e-9)):.3g}): pass float32 or "
                          f"float64 values")


def positive_finite(name: str, value: float, unit: str) -> float:
    """Return ``value`` as float, or raise if it is not a positive finite number."""
    full_precision(name, value, unit)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DoefabError(f"{name} must be a number in {unit}, got {value!r}") from None
    if isinstance(value, bool):
        raise DoefabError(f"{name} must be a number in {unit}, got {value!r}")
    if not math.isfinite(v) or v <= 0:
        raise DoefabError(f"{name} must be positive and finite (in {unit}), got {value!r}")
    return v


def number_in(name: str, value, lo: float, hi: float, integer: bool = False, unit: str = "",
              lo_open: bool = False):
    """``value`` as an int (``integer``) or a finite float within [lo, hi] (lo excluded with ``lo_open``), or
    one error naming the argument, its unit and its range."""
    unit_txt = f" {unit}" if unit else ""
    ok_type = isinstance(value, (int, np.integer)) if integer else isinstance(value, (int, float, np.number))
    if isinstance(value, bool) or not ok_type:
        raise DoefabError(f"{name} must be {'an integer' if integer else 'a number'}{unit_txt}, got {value!r}")
    v = int(value) if integer else float(value)
    if not math.isfinite(v) or (v <= lo if lo_open else v < lo) or v > hi:
        raise DoefabError(f"{name} must be {'>' if lo_open else '≥'} {lo:g} and ≤ {hi:g}{unit_txt}, got {value!r}")
    return v


INF_WORDS = ("inf", "infinity")  # how a TOML or JSON file may write a distance at infinity (any case), besides inf


def distance_or_inf(value) -> float | None:
    """A distance as read from a file: the number (metres), ``math.inf`` for TOML's ``inf`` or one of ``INF_WORDS``
    (JSON has no infinity), or None for anything else (a bool, another word, NaN). The range is the caller's.

    Example: ``[distance_or_inf(v) for v in (2, "inf", float("inf"), "far")]`` → ``[2.0, inf, inf, None]``.
    """
    if isinstance(value, str):
        return math.inf if value.strip().lower() in INF_WORDS else None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or math.isnan(value):
        return None
    return float(value)


def distance_record(z: float) -> float | str:
    """A distance (metres) as a JSON record writes it: the number, or ``"inf"`` for a point at infinity.

    Example: ``distance_record(float("inf"))`` → ``"inf"``; ``distance_record(2)`` → ``2.0``.
    """
    if z == math.inf:
        return INF_WORDS[0]
    if not math.isfinite(z):
        raise DoefabError(f"a distance must be a number or +inf, got {z!r}")
    return float(z)


_METRE_PREFIXES = (("nm", 1e-9), ("µm", 1e-6), ("mm", 1e-3))


def metres_hint(value: float, lo: float, hi: float) -> str:
    """`` (550 nm is 5.5e-07 m)`` when ``value`` read in nm, µm or mm lies within [lo, hi] metres (the likely unit
    slip), else ''."""
    for unit, factor in _METRE_PREFIXES:
        if lo <= value * factor <= hi:
            return f" ({value:g} {unit} is {value * factor:.4g} m)"
    return ""


LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "µm": 1e-6, "nm": 1e-9}  # metres per unit


def unit_hint(value: float, lo: float, hi: float, unit: str) -> str:
    """`` (5.5e-07 m is 550 nm: write 550)`` when ``value`` read in another length unit lies within [lo, hi]
    ``unit`` (the likely unit slip in a key or flag that names its unit), else ''."""
    per = LENGTH_UNITS.get(unit)
    if per is None or not value:
        return ""
    for other, factor in LENGTH_UNITS.items():
        v = value * factor / per
        if other != unit and lo <= v <= hi:
            return f" ({value:g} {other} is {v:.4g} {unit}: write {v:.4g})"
    return ""


def length_m(name: str, value: float, lo: float, hi: float, what: str = "lengths") -> float:
    """``value`` as a float within [lo, hi] metres, or one error with the unit hint."""
    v = positive_finite(name, value, "metres")
    if not lo <= v <= hi:
        raise DoefabError(f"{name} = {value!r} m is outside {lo:g}–{hi:g} m: {what} are in metres"
                          f"{metres_hint(v, lo, hi)}")
    return v


def wavelength_m(name: str, value: float) -> float:
    """A wavelength in metres (sanity range 100 nm – 20 µm)."""
    return length_m(name, value, 100e-9, 20e-6, "wavelengths")


def wavelengths(values: Iterable[float]) -> tuple[float, ...]:
    """Validate a non-empty list of wavelengths in metres (sanity range 100 nm – 20 µm)."""
    return tuple(wavelength_m("wavelength", v) for v in _as_tuple("wavelengths", values))


def seed(name: str, value) -> int:
    """A random seed: an integer 0 ≤ seed < 2**63."""
    return number_in(name, value, 0, 2**63 - 1, integer=True)


def heights(name: str, values) -> None:
    """A height map (metres; numpy or torch, not half precision) must be finite and within ±1 mm (a DOE step is
    ~1e-7 m)."""
    full_precision(name, values)
    a = np.asarray(values.detach().cpu() if hasattr(values, "detach") else values, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise DoefabError(f"{name} contains {int((~np.isfinite(a)).sum())} NaN or infinite values: every height must "
                          f"be finite (metres)")
    top = float(np.abs(a).max(initial=0.0))
    if top > 1e-3:
        raise DoefabError(f"{name} holds heights up to {top:g} m: heights are in metres (a DOE step is ~1e-7 m)"
                          f"{metres_hint(top, 1e-7, 1e-3)}")  # a relief's top: 0.1 µm (λ/4 steps) to 1 mm


def sensor_position(name: str, value) -> tuple[float, float]:
    """A (u, v) position on the sensor in metres (within ±10 cm of the axis)."""
    try:
        u, v = (float(x) for x in value)
    except (TypeError, ValueError):
        raise DoefabError(f"{name} must be a (u, v) sensor position in metres, got {value!r}") from None
    for x in (u, v):
        if not math.isfinite(x) or abs(x) > 0.1:
            raise DoefabError(f"{name} {value!r} is not on a sensor (|u|, |v| ≤ 0.1 m): positions are in metres"
                              f"{metres_hint(abs(x), 0.0, 0.1) if math.isfinite(x) else ''}")
    return u, v


def depths(values: Iterable[float]) -> tuple[float, ...]:
    """Validate a non-empty list of point-source depths in metres (> 0 and ≤ 1000 km, ``inf`` allowed)."""
    vals = _as_tuple("depths", values)
    out = []
    for v in vals:
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise DoefabError(f"depth must be a number in metres or inf, got {v!r}") from None
        if math.isnan(f) or f <= 0:
            raise DoefabError(f"depth must be > 0 m (or inf for a plane wave), got {v!r}")
        if math.isfinite(f) and f > 1e6:
            raise DoefabError(f"depth {v!r} m is beyond 1000 km: write inf for a point at infinity")
        out.append(f)
    return tuple(out)


def repeated(values) -> list:
    """The values that occur more than once in ``values``, each once, sorted.

    Example: ``repeated([2.0, 1.0, 2.0, 3.0, 1.0])`` → ``[1.0, 2.0]``."""
    return sorted({v for i, v in enumerate(values) if v in values[:i]})


def _as_tuple(name: str, values) -> tuple:
    full_precision(name, values)
    if getattr(values, "requires_grad", False):
        raise DoefabError(f"{name} is a tensor that requires grad: the PSF is differentiable in the height maps "
                          f"only; pass plain numbers (e.g. {name}.detach())")
    if isinstance(values, (int, float)):
        values = [values]
    try:
        vals = tuple(np.asarray(values, dtype=float).ravel().tolist()) if not isinstance(values, Sequence) \
            else tuple(values)
    except (TypeError, ValueError):
        raise DoefabError(f"{name} must be a list of numbers, got {values!r}") from None
    if len(vals) == 0:
        raise DoefabError(f"{name} is empty: give at least one value")
    return vals
