"""The sensor: its RGB response to spectral bands (the paper's Eq. 23's T_s) and its noise, and ``Sensor``, the
two together as a scene or a set of weights names them.

Responses: ``imaging.responses`` (the Canon EOS 5D Mark II rawtoaces curves by default; the Nikon D5100 and Sigma
SD Merrill NPL curves, or a user's CSV).

Noise (``PoissonGaussian``): shot noise of the photo-electrons plus Gaussian read noise, in units of the
full-well signal (a capture value of 1 = a full sub-pixel). Defaults: 25 000 e⁻ full well per dual-pixel
photodiode (about half of the ~50 000 e⁻ reported for a whole 5.4 µm pixel of full-frame sensors of that
generation) and 3 e⁻ read noise at base ISO — typical published values, not our measurements; pass your
sensor's. ``"authors"`` is the uniform ±0.01 noise of the authors' released code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.responses import DEFAULT_RESPONSE, is_named, response_curves, response_label, response_sha256

__all__ = ["sensor_response", "bands_outside", "PoissonGaussian", "UniformNoise", "noise_model", "RESPONSE_SOURCE",
           "Sensor", "sensor_from_record", "noise_fields", "DEFAULT_FULL_WELL_E", "DEFAULT_READ_NOISE_E", "FULL_WELL_RANGE_E",
           "READ_NOISE_RANGE_E", "MIN_CHANNEL_FRACTION"]

DEFAULT_FULL_WELL_E = 25_000.0  # electrons per dual-pixel photodiode at capture value 1 (module docstring)
DEFAULT_READ_NOISE_E = 3.0  # electrons rms at base ISO
FULL_WELL_RANGE_E = (100.0, 1e7)  # what a scene, a flag and ``Sensor`` accept
READ_NOISE_RANGE_E = (0.0, 1000.0)

RESPONSE_SOURCE = ("Canon EOS 5D Mark II RGB sensitivities (rawtoaces), shipped by colour-science as "
                   "characterisation/datasets/rawtoaces/CANON_EOS_5DMark_II_RGB_Sensitivities.csv")


def bands_outside(wavelengths, source=DEFAULT_RESPONSE) -> tuple[np.ndarray, str]:
    """(the ``wavelengths`` (metres) outside ``source``'s measured response, that response's range in words).

    Example: ``bands_outside([1000e-9])`` is ([1e-06], "the Canon EOS 5D Mark II response's 380–780 nm")."""
    src_lam = response_curves(source)[0]
    return _outside(np.asarray(wavelengths, np.float64).ravel(), src_lam), _range_words(source, src_lam)


def _outside(lam: np.ndarray, src_lam: np.ndarray) -> np.ndarray:
    return lam[(lam < src_lam[0] - 1e-12) | (lam > src_lam[-1] + 1e-12)]


def _range_words(source, src_lam: np.ndarray) -> str:
    return f"the {response_label(source)} response's {src_lam[0] * 1e9:.0f}–{src_lam[-1] * 1e9:.0f} nm"


def sensor_response(wavelengths, source=DEFAULT_RESPONSE, every_channel: bool = False) -> np.ndarray:
    """[3, C] float32 RGB response for bands at ``wavelengths`` (metres, within the curves' range), linearly
    interpolated from ``source`` (a camera name of ``imaging.responses.RESPONSES`` or a CSV path).

    Normalised so that a flat spectrum of radiance 1 in every band gives 1 in the most sensitive channel
    (summed over the given bands): a white spectral scene and an RGB scene of value 1 expose alike. With
    ``every_channel`` (a spectral task's bands, which every channel must image), bands that one of R, G, B barely
    sees (on average below ``MIN_CHANNEL_FRACTION`` of its peak) are refused; without it a narrow-band source (a
    633 nm laser, which blue does not see) is fine.

    Example:

        >>> import doefab
        >>> r = doefab.sensor_response([633e-9])  # (3 channels, 1 band), the strongest channel's peak 1
        >>> r.shape, int(r.argmax())  # red sees a 633 nm laser most
        ((3, 1), 0)
    """
    lam = np.asarray(wavelengths, np.float64).ravel()
    if lam.size == 0 or not np.all(np.isfinite(lam)):
        raise DoefabError("wavelengths must be a non-empty list of finite numbers in metres")
    src_lam, curves = response_curves(source)
    if (out := _outside(lam, src_lam)).size:
        hint = " (they look like nanometres: pass metres, e.g. 550e-9)" if lam.max() > 1 else ""
        bands = (", ".join(f"{v:g}" for v in out) + " m") if hint else (", ".join(f"{v * 1e9:.4g}" for v in out)
                                                                        + " nm")
        raise DoefabError(f"wavelengths {bands} lie outside {_range_words(source, src_lam)}{hint}: keep the bands "
                          f"within it, or give a response that covers them")
    peak = curves.max(axis=1)  # > 0 for every channel (responses.py refuses a dark one)
    seen = np.stack([np.interp(lam, src_lam, c / p) for c, p in zip(curves, peak)])  # each channel ≤ 1: no overflow
    if every_channel:
        _check_channels_see(seen, lam, source)
    t = seen * (peak / peak.max())[:, None]  # the channels' relative gains, as the curves give them
    return (t / t.sum(axis=1).max()).astype(np.float32)


#: A channel must average at least this fraction of its own peak sensitivity over the bands (its integral over
#: the band range ≥ 1 % of peak × bandwidth). Colour filters block out of band to a few % of their peak; a channel
#: below 1 % sees the bands only through that leakage, and its capture holds little but noise.
MIN_CHANNEL_FRACTION = 0.01


def _check_channels_see(seen: np.ndarray, lam: np.ndarray, source) -> None:
    """Refuse bands that one of R, G, B barely sees: ``seen`` [3, C] is each channel relative to its peak."""
    mean = seen.mean(axis=1)
    blind = [f"{c} {m * 100:.2g} %" if m >= 1e-4 else f"{c} < 0.01 %" for c, m in zip("RGB", mean)
             if m < MIN_CHANNEL_FRACTION]
    if blind:
        bands = f"{lam.min() * 1e9:.4g}–{lam.max() * 1e9:.4g} nm" if lam.size > 1 else f"{lam[0] * 1e9:.4g} nm"
        raise DoefabError(f"the {response_label(source)} response barely sees the bands {bands}: over them "
                          f"{', '.join(blind)} of its peak sensitivity on average (each of R, G and B needs ≥ "
                          f"{MIN_CHANNEL_FRACTION * 100:g} %): choose bands each channel sees, or a response "
                          f"measured over them")


@dataclass(frozen=True)
class PoissonGaussian:
    """Shot + read noise. ``full_well_e``: electrons at capture value 1; ``read_noise_e``: rms electrons."""

    full_well_e: float = DEFAULT_FULL_WELL_E
    read_noise_e: float = DEFAULT_READ_NOISE_E

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
    """``"default"`` (PoissonGaussian()), ``"authors"`` (uniform ±0.01), ``"none"``, a model object, or a
    ``Sensor`` (its shot and read noise)."""
    if hasattr(noise, "apply"):
        return noise
    if isinstance(noise, Sensor):
        return noise.noise()
    presets = {"default": PoissonGaussian(), "authors": UniformNoise(0.01), "none": NoNoise()}
    if noise is None:
        return presets["none"]
    if not isinstance(noise, str) or noise not in presets:
        raise DoefabError(f"noise must be one of {sorted(presets)} or a noise model, got {noise!r}")
    return presets[noise]


@dataclass(frozen=True)
class Sensor:
    """A camera's sensor as the captures see it: its RGB response (a camera name of
    ``imaging.responses.RESPONSES`` or a CSV path) and its noise (``full_well_e``: electrons at a capture value of
    1, within ``FULL_WELL_RANGE_E``; ``read_noise_e``: rms electrons, within ``READ_NOISE_RANGE_E``). The default
    is the prototype's (Canon EOS 5D Mark II curves, 25 000 e⁻, 3 e⁻). A CSV response is read and checked when
    the sensor is made; a named one when first used.

    Example:

        >>> import doefab
        >>> s = doefab.Sensor(full_well_e=10000.0, read_noise_e=2.0)  # electrons
        >>> s.response, s.full_well_e
        ('Canon EOS 5D Mark II', 10000.0)
    """

    response: str = DEFAULT_RESPONSE
    full_well_e: float = DEFAULT_FULL_WELL_E
    read_noise_e: float = DEFAULT_READ_NOISE_E

    def __post_init__(self):
        from doefab.validate import number_in

        number_in("full_well_e", self.full_well_e, *FULL_WELL_RANGE_E, unit="electrons")
        number_in("read_noise_e", self.read_noise_e, *READ_NOISE_RANGE_E, unit="electrons rms")
        if self.read_noise_e >= self.full_well_e:
            raise DoefabError(f"read_noise_e {self.read_noise_e:g} electrons rms reaches full_well_e "
                              f"{self.full_well_e:g} electrons: such a sensor records no signal above its noise "
                              f"(a dynamic range of 0 stops or less); check the two values (a camera's read noise is "
                              f"a few electrons, its full well thousands)")
        if not is_named(self.response):
            response_curves(self.response)  # a missing or malformed CSV is refused here, before any work

    def noise(self) -> PoissonGaussian:
        """The shot and read noise of this sensor (``PoissonGaussian``)."""
        return PoissonGaussian(float(self.full_well_e), float(self.read_noise_e))

    def rgb(self, wavelengths) -> np.ndarray:
        """[3, C] response on a spectral task's bands at ``wavelengths`` (metres; ``sensor_response``), each of
        R, G and B required to see them."""
        return sensor_response(wavelengths, self.response, every_channel=True)

    def has_default_response(self) -> bool:
        """Whether the response's curves are the default camera's (by content, not by name)."""
        return self.response == DEFAULT_RESPONSE or response_sha256(self.response) == response_sha256(DEFAULT_RESPONSE)

    def record(self, with_response: bool = True) -> dict:
        """What weights and results record: the noise (e⁻) and, ``with_response`` (the spectral task, whose
        captures it forms), the response's label and the SHA-256 of its curves."""
        out = {"full_well_e": float(self.full_well_e), "read_noise_e": float(self.read_noise_e)}
        if with_response:
            out = {"response": response_label(self.response), "response_sha256": response_sha256(self.response),
                   **out}
        return out

    def entry(self, spectral: bool) -> dict:
        """``{"sensor": record}`` for records (training runs, weights, evaluations, stage hashes) when this is not
        the default sensor — in what a task uses: the noise, and the response if ``spectral`` — else ``{}``: a
        record without it is the default sensor's, as every record made before sensors could be named."""
        return {"sensor": self.record(with_response=spectral)} if self.differs_from(None, spectral) else {}

    def describe(self, with_response: bool = True) -> str:
        """One line for reports: response (``with_response``), full well and read noise with their units."""
        noise = f"{self.full_well_e:g} e⁻ full well, {self.read_noise_e:g} e⁻ read noise"
        return f"{response_label(self.response)} response, {noise}" if with_response else noise

    def differs_from(self, record: dict | None, spectral: bool) -> list[str]:
        """What of this sensor another's ``record`` does not share (its missing entries, or a None record: the
        default sensor's): the noise, and the response where it forms the captures (``spectral``: hyperspectral
        scenes; RGB scenes are the camera's own)."""
        other = record or {}
        out = [f"{k} {other.get(k, d):g} (this camera: {getattr(self, k):g})"
               for k, d in (("full_well_e", DEFAULT_FULL_WELL_E), ("read_noise_e", DEFAULT_READ_NOISE_E))
               if not math.isclose(float(other.get(k, d)), float(getattr(self, k)), rel_tol=1e-9)]
        if spectral:
            theirs = other.get("response_sha256") or response_sha256(DEFAULT_RESPONSE)
            if theirs != response_sha256(self.response):
                out.insert(0, f"response {other.get('response', DEFAULT_RESPONSE)} (this camera: "
                              f"{response_label(self.response)})")
        return out


def sensor_from_record(record: dict | None) -> Sensor:
    """The noise of a weights record's ``sensor`` entry (its response stays the default's: a record names a
    response, it does not carry its curves — a spectral network's architecture record does); the default sensor
    for records that predate it."""
    r = record if isinstance(record, dict) else {}
    return Sensor(**noise_fields(r))


def noise_fields(mapping: dict) -> dict:
    """The ``Sensor`` noise fields a record or a scene's ``[sensor]`` table gives (as floats; absent ones keep
    the defaults)."""
    return {k: float(mapping[k]) for k in ("full_well_e", "read_noise_e") if k in mapping}
