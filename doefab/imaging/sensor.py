"""The sensor's RGB response to spectral bands (the paper's Eq. 23's T_s) and its noise models.

Response source: the Canon EOS 5D Mark II RGB spectral sensitivities measured for the Academy's rawtoaces
project, as shipped by the ``colour-science`` package
(``colour/characterisation/datasets/rawtoaces/CANON_EOS_5DMark_II_RGB_Sensitivities.csv``, 380–780 nm at
5 nm). The paper's camera is a 5D Mark IV, whose curves are not published in any package; the Mark II is the
nearest Canon full-frame sensor with public curves.

Noise (``PoissonGaussian``): shot noise of the photo-electrons plus Gaussian read noise, in units of the
full-well signal (a capture value of 1 = a full sub-pixel). Defaults: 25 000 e⁻ full well per dual-pixel
photodiode (about half of the ~50 000 e⁻ reported for a whole 5.4 µm pixel of full-frame sensors of that
generation) and 3 e⁻ read noise at base ISO — typical published values, not our measurements; pass your
sensor's. ``"authors"`` is the uniform ±0.01 noise of the authors' released code.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError

__all__ = ["sensor_response", "PoissonGaussian", "UniformNoise", "noise_model", "RESPONSE_SOURCE"]

RESPONSE_SOURCE = ("Canon EOS 5D Mark II RGB sensitivities (rawtoaces), shipped by colour-science as "
                   "characterisation/datasets/rawtoaces/CANON_EOS_5DMark_II_RGB_Sensitivities.csv")


def _curves() -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths in metres, [3, L] R, G, B sensitivities) from colour-science's data file."""
    try:
        from colour.characterisation.aces_it import ROOT_RESOURCES_RAWTOACES
    except ImportError:
        raise DoefabError("sensor_response needs the colour-science package: pip install colour-science") from None
    path = os.path.join(ROOT_RESOURCES_RAWTOACES, "CANON_EOS_5DMark_II_RGB_Sensitivities.csv")
    data = np.genfromtxt(path, delimiter=",", names=True)
    lam = np.asarray(data["wavelength"], np.float64) * 1e-9
    return lam, np.stack([np.asarray(data[c], np.float64) for c in ("R", "G", "B")])


def sensor_response(wavelengths) -> np.ndarray:
    """[3, C] float32 RGB response for bands at ``wavelengths`` (metres, 380–780 nm), linearly interpolated.

    Normalised so that a flat spectrum of radiance 1 in every band gives 1 in the most sensitive channel
    (summed over the given bands): a white spectral scene and an RGB scene of value 1 expose alike.
    """
    lam = np.asarray(wavelengths, np.float64).ravel()
    if lam.size == 0 or not np.all(np.isfinite(lam)):
        raise DoefabError("wavelengths must be a non-empty list of finite numbers in metres")
    src_lam, curves = _curves()
    if lam.min() < src_lam[0] - 1e-12 or lam.max() > src_lam[-1] + 1e-12:
        hint = " (they look like nanometres: pass metres, e.g. 550e-9)" if lam.max() > 1 else ""
        raise DoefabError(f"wavelengths {lam.min():g}–{lam.max():g} m lie outside the sensor data's "
                          f"{src_lam[0] * 1e9:.0f}–{src_lam[-1] * 1e9:.0f} nm{hint}")
    t = np.stack([np.interp(lam, src_lam, c) for c in curves])
    return (t / t.sum(axis=1).max()).astype(np.float32)


@dataclass(frozen=True)
class PoissonGaussian:
    """Shot + read noise. ``full_well_e``: electrons at capture value 1; ``read_noise_e``: rms electrons."""

    full_well_e: float = 25_000.0
    read_noise_e: float = 3.0

    def __post_init__(self):
        if not (math.isfinite(self.full_well_e) and self.full_well_e > 0):
            raise DoefabError(f"full_well_e must be a positive number of electrons, got {self.full_well_e!r}")
        if not (math.isfinite(self.read_noise_e) and self.read_noise_e >= 0):
            raise DoefabError(f"read_noise_e must be ≥ 0 electrons, got {self.read_noise_e!r}")

    def apply(self, img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        electrons = rng.poisson(np.clip(img, 0, None) * self.full_well_e).astype(np.float64)
        electrons += rng.normal(0.0, self.read_noise_e, img.shape)
        return electrons / self.full_well_e


@dataclass(frozen=True)
class UniformNoise:
    """Uniform noise in ±``amplitude`` (the authors' released code uses ±0.01)."""

    amplitude: float = 0.01

    def apply(self, img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return img + rng.uniform(-self.amplitude, self.amplitude, img.shape)


@dataclass(frozen=True)
class NoNoise:
    def apply(self, img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return img


def noise_model(noise):
    """``"default"`` (PoissonGaussian()), ``"authors"`` (uniform ±0.01), ``"none"``, or a model object."""
    if hasattr(noise, "apply"):
        return noise
    presets = {"default": PoissonGaussian(), "authors": UniformNoise(0.01), "none": NoNoise()}
    if noise is None:
        return presets["none"]
    if not isinstance(noise, str) or noise not in presets:
        raise DoefabError(f"noise must be one of {sorted(presets)} or a noise model, got {noise!r}")
    return presets[noise]
