"""Small input checks shared by the public API (one clear error per problem)."""

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
    if not math.isfinite(v) or v <= 0:
        raise DoefabError(f"{name} must be positive and finite (in {unit}), got {value!r}")
    return v


def wavelengths(values: Iterable[float]) -> tuple[float, ...]:
    """Validate a non-empty list of wavelengths in metres (sanity range 100 nm – 20 µm)."""
    vals = _as_tuple("wavelengths", values)
    for v in vals:
        positive_finite("wavelength", v, "metres")
        if not 100e-9 <= v <= 20e-6:
            raise DoefabError(
                f"wavelength {v!r} m is outside 100 nm – 20 µm: wavelengths are in metres "
                f"(write 550e-9, not 550)")
    return tuple(float(v) for v in vals)


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
