"""The spectral grid of the hyperspectral task and colour-science's spectra on it: 31 bands, 400–700 nm every
10 nm (``HS_WAVELENGTHS_M``), a spectral distribution resampled there (``on_bands``) and the illuminants
(``illuminant_spectra``). The scenes (``data``), reflectances (``spectra``) and illuminant library
(``illuminant``) all read them from here."""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["HS_WAVELENGTHS_M", "on_bands", "illuminant_spectra"]

HS_WAVELENGTHS_M = tuple(float(x) * 1e-9 for x in range(400, 701, 10))


def on_bands(sd) -> np.ndarray:
    """A colour-science spectral distribution on the 31 bands 400–700 nm (10 nm).

    Example: ``on_bands(colour.SDS_ILLUMINANTS["D65"])`` → a (31,) array."""
    import colour

    return np.asarray(sd.copy().align(colour.SpectralShape(400, 700, 10)).values, np.float64)


@functools.lru_cache(maxsize=None)
def illuminant_spectra() -> tuple[tuple[str, ...], np.ndarray]:
    """(names, [I, 31]) colour-science's illuminants on 400–700 nm, ISO ones excluded, normalised to peak 1."""
    import colour

    names, rows = [], []
    for n in colour.SDS_ILLUMINANTS:
        e = on_bands(colour.SDS_ILLUMINANTS[n])
        if not n.startswith("ISO") and np.all(np.isfinite(e)) and e.max() > 0:
            names.append(n)
            rows.append(e / e.max())
    return tuple(names), np.array(rows)
