"""Small input checks shared by the public API (one clear error per problem, naming the argument, its unit and
the fix; a length typed in the wrong unit gets the conversion: "550 nm is 5.5e-07 m")."""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from doefab.errors import DoefabError


def positive_finite(name: str, value: float, unit: str) -> float:
    """Return ``value`` as float, or raise if it is not a positive finite number."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DoefabError(f"{name} must be a number in {unit}, got {value!r}") from None
    if isinstance(value, bool):
        raise DoefabError(f"{name} must be a number in {unit}, got {value!r}")
    if not math.isfinite(v) or v <= 0:
        raise DoefabError(f"{name} must be positive and finite (in {unit}), got {value!r}")
    return v


_METRE_PREFIXES = (("nm", 1e-9), ("µm", 1e-6), ("mm", 1e-3))


def metres_hint(value: float, lo: float, hi: float) -> str:
    """`` (550 nm is 5.5e-07 m)`` when ``value`` read in nm, µm or mm lies within [lo, hi] metres (the likely unit
    slip), else ''."""
    for unit, factor in _METRE_PREFIXES:
        if lo <= value * factor <= hi:
            return f" ({value:g} {unit} is {value * factor:.4g} m)"
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


def depths(values: Iterable[float]) -> tuple[float, ...]:
    """Validate a non-empty list of point-source depths in metres (> 0, ``inf`` allowed)."""
    vals = _as_tuple("depths", values)
    out = []
    for v in vals:
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise DoefabError(f"depth must be a number in metres or inf, got {v!r}") from None
        if math.isnan(f) or f <= 0:
            raise DoefabError(f"depth must be > 0 m (or inf for a plane wave), got {v!r}")
        out.append(f)
    return tuple(out)


def _as_tuple(name: str, values) -> tuple:
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
