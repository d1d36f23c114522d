"""Refractive index of DOE substrates (Sellmeier dispersion).

The default substrate is fused silica (Malitson 1965, see ../shared/DESIGN-NOTES.md):
``n² − 1 = Σ B_i λ² / (λ² − C_i²)`` with λ in micrometres inside the formula; the public functions take
and return SI units (metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError

__all__ = ["Material", "FUSED_SILICA", "material_by_name"]


@dataclass(frozen=True)
class Material:
    """A dispersive substrate described by a three-term Sellmeier formula.

    Attributes:
        name: human-readable name, stored in design and mask manifests.
        b: Sellmeier B coefficients (dimensionless), three values.
        c_um: Sellmeier C coefficients in micrometres (the resonance wavelengths), three values.
    """

    name: str
    b: tuple[float, float, float]
    c_um: tuple[float, float, float]

    def __post_init__(self) -> None:
        """Three finite, non-negative B (≤ 100, not all 0) and C coefficients; a C below 1e-4 µm is a resonance
        typed in metres."""
        for key, vals, hi in (("sellmeier_b", self.b, 100.0), ("sellmeier_c_um", self.c_um, 1e4)):
            ok = isinstance(vals, (tuple, list)) and len(vals) == 3 and all(
                isinstance(x, (int, float, np.number)) and not isinstance(x, bool) and math.isfinite(x)
                and 0 <= x <= hi for x in vals)
            if not ok:
                raise DoefabError(f"Material {key} must be three finite numbers in 0–{hi:g}, got {vals!r}")
        if not any(self.b):
            raise DoefabError("Material sellmeier_b are all 0: the index would be 1 (no phase delay)")
        if any(0 < c < 1e-4 for c in self.c_um):
            raise DoefabError(f"Material sellmeier_c_um {self.c_um!r}: resonance wavelengths are in micrometres "
                              f"(0.068 for fused silica), not metres")

    def index(self, wavelength_m):
        """Refractive index at ``wavelength_m`` (metres; scalar or array) -> same shape, float64."""
        lam_um = np.asarray(wavelength_m, dtype=np.float64) * 1e6
        if np.any(~np.isfinite(lam_um)) or np.any(lam_um <= 0):
            raise DoefabError(f"wavelength must be positive and finite in metres, got {wavelength_m!r}")
        l2 = lam_um**2
        n2 = 1.0 + sum(bi * l2 / (l2 - ci**2) for bi, ci in zip(self.b, self.c_um))
        return np.sqrt(n2)

    def height_2pi(self, wavelength_m: float) -> float:
        """Height (metres) of material that delays light of ``wavelength_m`` by one wave: λ / (n − 1)."""
        return float(wavelength_m / (self.index(wavelength_m) - 1.0))

    def to_dict(self) -> dict:
        """JSON-ready record: ``name``, ``sellmeier_b`` and ``sellmeier_c_um`` (micrometres)."""
        return {"name": self.name, "sellmeier_b": list(self.b), "sellmeier_c_um": list(self.c_um)}

    @classmethod
    def from_dict(cls, d: dict, where: str = "material record") -> "Material":
        """A material from :meth:`to_dict`'s record, its fields checked (name, three finite B and C values)."""
        if not isinstance(d, dict) or not isinstance(d.get("name"), str) or not d["name"].strip():
            raise DoefabError(f"{where}: needs a name and sellmeier_b, sellmeier_c_um (three numbers each)")
        coeffs = []
        for key in ("sellmeier_b", "sellmeier_c_um"):
            v = d.get(key)
            if not isinstance(v, list) or len(v) != 3 or not all(isinstance(x, (int, float)) for x in v):
                raise DoefabError(f"{where}: {key} must be three numbers, got {v!r}")
            coeffs.append(tuple(float(x) for x in v))
        try:
            made = cls(d["name"], coeffs[0], coeffs[1])
        except DoefabError as exc:
            raise DoefabError(f"{where}: {exc}") from None
        known = _MATERIALS.get(d["name"].lower())
        if known is not None and (known.b, known.c_um) != (coeffs[0], coeffs[1]):
            raise DoefabError(f"{where}: {d['name']!r} is a built-in material but its Sellmeier coefficients differ "
                              f"from the built-in ones: the record was edited; restore them or rename the material")
        return made


#: Fused silica by Malitson's Sellmeier formula (C coefficients in micrometres): the default DOE substrate.
FUSED_SILICA = Material(
    name="fused silica",
    b=(0.6961663, 0.4079426, 0.8974794),
    c_um=(0.0684043, 0.1162414, 9.896161),
)

_MATERIALS = {"fused silica": FUSED_SILICA, "fused_silica": FUSED_SILICA}


def material_by_name(name: str) -> Material:
    """Look up a built-in material by name (``"fused silica"``)."""
    try:
        return _MATERIALS[name.lower()]
    except KeyError:
        raise DoefabError(
            f"unknown material {name!r}: built-in ones are {sorted(set(_MATERIALS))}; "
            f"pass a doefab.Material for others") from None
