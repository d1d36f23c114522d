"""Refractive index of DOE substrates (Sellmeier dispersion) and the built-in table of published ones.

Every substrate is a three-term Sellmeier formula ``n² − 1 = Σ B_i λ² / (λ² − C_i²)`` with λ and the resonance
wavelengths C_i in micrometres inside the formula (sources that publish C_i² in µm², like SCHOTT's catalogue, are
converted by a square root here, once); the public functions take and return SI units (metres). The indices are
relative to air, as the sources give them.

Built-in substrates (``substrate_name`` resolves a name in any case, spaces, ``-`` and ``_`` alike, for the API's
``material_by_name`` and for scene files; ``SUBSTRATES`` holds each source and the wavelength range its fit
covers):

- ``"fused silica"``: I. H. Malitson, "Interspecimen comparison of the refractive index of fused silica",
  J. Opt. Soc. Am. 55, 1205–1209 (1965); 0.21–3.71 µm, 20 °C.
- ``"N-BK7"``: SCHOTT AG, optical glass data sheet N-BK7 (Sellmeier B1–B3, C1–C3 in µm²; Zemax catalogue
  2017-01-20); 0.3–2.5 µm, 20 °C.
- ``"CaF2"``: I. H. Malitson, "A redetermination of some optical properties of calcium fluoride", Appl. Opt. 2,
  1103–1107 (1963); 0.23–9.7 µm, 24 °C.
- ``"sapphire"`` (ordinary ray, i.e. light along the c axis of a c-cut window): I. H. Malitson and M. J. Dodge,
  "Refractive index and birefringence of synthetic sapphire", J. Opt. Soc. Am. 62, 1405 (1972), with the
  Sellmeier coefficients of M. J. Dodge, "Refractive index", Handbook of Laser Science and Technology Vol. IV,
  Optical Materials Part 2, CRC Press (1986), p. 30; 0.2–5.0 µm, 20 °C.
- ``"PMMA"``: N. Sultanova, S. Kasarova, I. Nikolov, "Dispersion properties of optical polymers", Acta Physica
  Polonica A 116, 585–587 (2009), as the one-term Sellmeier fit of their data by M. N. Polyanskiy
  (refractiveindex.info): n² − 1 = 1.1819 λ² / (λ² − 0.011313 µm²); 0.4368–1.052 µm, 20 °C.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError

__all__ = ["Material", "Substrate", "FUSED_SILICA", "N_BK7", "CAF2", "SAPPHIRE", "PMMA", "SUBSTRATES",
           "material_by_name", "substrate_name", "fit_range_warning"]


@dataclass(frozen=True)
class Material:
    """A dispersive substrate described by a three-term Sellmeier formula (a one- or two-term source has zeros).

    Attributes:
        name: human-readable name, stored in design and mask manifests.
        b: Sellmeier B coefficients (dimensionless), three values.
        c_um: Sellmeier C coefficients in micrometres (the resonance wavelengths), three values.

    Example:

        >>> import doefab
        >>> silica = doefab.Material("fused silica", b=(0.6961663, 0.4079426, 0.8974794),
        ...                          c_um=(0.0684043, 0.1162414, 9.896161))
        >>> round(float(silica.index(587.6e-9)), 4)  # n_d, the Malitson (1965) Sellmeier
        1.4585
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
        """Refractive index at ``wavelength_m`` (metres, 100 nm – 20 µm; scalar or array) -> same shape, float64.

        Example: ``FUSED_SILICA.index(550e-9)`` → 1.45991 (``index(550)``, nanometres, is refused)."""
        from doefab.validate import wavelength_m as checked

        lam_um = np.asarray(wavelength_m, dtype=np.float64) * 1e6
        if np.any(~np.isfinite(lam_um)) or np.any(lam_um <= 0):
            raise DoefabError(f"wavelength must be positive and finite in metres, got {wavelength_m!r}")
        lam = np.asarray(wavelength_m, dtype=np.float64).ravel()
        out = lam[(lam < 100e-9) | (lam > 20e-6)]
        if out.size:
            checked("wavelength", float(out[0]))  # refuses the first out of range, with its unit hint
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
        builtin = _NAMES.get(_key(d["name"]))
        known = SUBSTRATES[builtin].material if builtin else None
        if known is not None and (known.b, known.c_um) != (coeffs[0], coeffs[1]):
            raise DoefabError(f"{where}: {d['name']!r} is a built-in material but its Sellmeier coefficients differ "
                              f"from the built-in ones: the record was edited; restore them or rename the material")
        return made


def _roots(*c2_um2: float) -> tuple[float, ...]:
    """Resonance wavelengths C_i (µm) from coefficients published as C_i² (µm²)."""
    return tuple(math.sqrt(c) for c in c2_um2)


@dataclass(frozen=True)
class Substrate:
    """A built-in substrate: its dispersion, where it was published, and the wavelengths (µm) the fit covers."""

    material: Material
    source: str
    range_um: tuple[float, float]


#: Fused silica (Malitson 1965; Sellmeier C coefficients in µm, fit 0.21–3.71 µm): the default DOE substrate.
FUSED_SILICA = Material(name="fused silica", b=(0.6961663, 0.4079426, 0.8974794),
                        c_um=(0.0684043, 0.1162414, 9.896161))
#: SCHOTT N-BK7 (data sheet; C_i² in µm² converted to C_i in µm, fit 0.3–2.5 µm).
N_BK7 = Material(name="N-BK7", b=(1.03961212, 0.231792344, 1.01046945),
                 c_um=_roots(0.00600069867, 0.0200179144, 103.560653))
#: Calcium fluoride (Malitson 1963; C in µm, fit 0.23–9.7 µm).
CAF2 = Material(name="CaF2", b=(0.5675888, 0.4710914, 3.8484723), c_um=(0.050263605, 0.1003909, 34.649040))
#: Sapphire, ordinary ray (Malitson & Dodge 1972; C in µm, fit 0.2–5.0 µm).
SAPPHIRE = Material(name="sapphire", b=(1.4313493, 0.65054713, 5.3414021), c_um=(0.0726631, 0.1193242, 18.028251))
#: PMMA (Sultanova et al. 2009, one-term fit; C in µm, fit 0.4368–1.052 µm).
PMMA = Material(name="PMMA", b=(1.1819, 0.0, 0.0), c_um=_roots(0.011313, 0.0, 0.0))

#: The built-in substrates by name: each one's Material, published source and fitted range (µm).
SUBSTRATES = {s.material.name: s for s in (
    Substrate(FUSED_SILICA, "Malitson, J. Opt. Soc. Am. 55, 1205 (1965)", (0.21, 3.71)),
    Substrate(N_BK7, "SCHOTT optical glass data sheet N-BK7", (0.3, 2.5)),
    Substrate(CAF2, "Malitson, Appl. Opt. 2, 1103 (1963)", (0.23, 9.7)),
    Substrate(SAPPHIRE, "Malitson & Dodge, J. Opt. Soc. Am. 62, 1405 (1972), ordinary ray", (0.2, 5.0)),
    Substrate(PMMA, "Sultanova, Kasarova & Nikolov, Acta Phys. Pol. A 116, 585 (2009)", (0.4368, 1.052)),
)}

def _key(name: str) -> str:
    """A name as the resolver compares it: lower case, without spaces, ``-`` or ``_``."""
    return "".join(c for c in name.lower() if c not in " -_\t")


_NAMES = {_key(name): name for name in SUBSTRATES}


def substrate_name(name) -> str:
    """The built-in substrate ``name`` means, as ``SUBSTRATES`` spells it: any case, with spaces, ``-`` or ``_``
    alike (``"Fused Silica"``, ``"fused_silica"``, ``"n-bk7"``, ``"caf2"``). The one resolver of substrate names,
    for ``material_by_name`` and for scene files; an unknown name is a DoefabError listing the built-in ones."""
    found = _NAMES.get(_key(name)) if isinstance(name, str) else None
    if found is None:
        raise DoefabError(f"unknown material {name!r}: choose a built-in substrate, "
                          f"{', '.join(map(repr, SUBSTRATES))} (any case)")
    return found


def material_by_name(name: str) -> Material:
    """A built-in substrate by name (``substrate_name``: ``"fused silica"``, ``"N-BK7"``, ``"CaF2"``,
    ``"sapphire"``, ``"PMMA"``, in any case).

    Example:

        >>> import doefab
        >>> glass = doefab.material_by_name("n-bk7")
        >>> glass.name, round(float(glass.index(587.6e-9)), 4)  # n_d
        ('N-BK7', 1.5168)
    """
    try:
        return SUBSTRATES[substrate_name(name)].material
    except DoefabError as exc:
        raise DoefabError(f"{exc}; for another, pass a doefab.Material with its Sellmeier coefficients") from None


def fit_range_warning(material: Material, wavelengths_m) -> str | None:
    """A sentence naming the wavelengths (metres) outside the range the built-in substrate's published fit
    covers (its index there is an extrapolation), or None (all inside, or not a built-in substrate)."""
    sub = SUBSTRATES.get(material.name)
    if sub is None or sub.material != material:
        return None
    lo, hi = sub.range_um
    nm = sorted({round(float(w) * 1e9, 6) for w in np.atleast_1d(np.asarray(wavelengths_m, np.float64))})
    out = [w for w in nm if not lo * 1e3 - 1e-6 <= w <= hi * 1e3 + 1e-6]  # compared in nm: 436.8 is inside 436.8
    if not out:
        return None
    return (f"{material.name}: {', '.join(f'{w:g} nm' for w in out)} outside {lo * 1e3:g}–{hi * 1e3:g} nm, "
            f"the range of its published dispersion ({sub.source}); the index there is extrapolated")
