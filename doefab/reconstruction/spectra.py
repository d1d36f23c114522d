"""Reflectances and illuminants of the hyperspectral scenes, split by content and open to light outside the
library the proposed network searches.

**Reflectances.** colour-science ships overlapping collections: the ISO 17321-1 chart is the ColorChecker N
Ohta measurement to 1e-6, the PMC chart re-measures ColorChecker patches, CIE 2024 repeats 14 of CIE 1995's
samples and NIST CQS 7.4 eight of CQS 9.0's. Each split takes whole families: test the ColorChecker (every
measurement of it) and the PMC chart, validation the NIST CQS samples, training the CIE test colour samples —
and every spectrum within ``DUPLICATE`` (``spectral_distance``: max absolute difference on the 31 bands after a
least-squares scale, as shading and exposure scale a surface; 0.035, the median gap between colour-science's two
measurements of one ColorChecker patch) of one in an earlier-ranked split (test, then validation) is dropped
from the later one, and from its own split when it repeats one there. Training also draws smooth synthetic
reflectances (never within ``DUPLICATE`` of a held-out one), so the networks do not learn a dozen spectra.

**Illuminants.** The proposed network searches a library (``doefab/weights/illuminants.csv``: colour-science's
CIE illuminants). Training scenes are lit by library members only. Validation and test scenes alternate: even
indices are lit by a library member (*in-library*: the search can find the light), odd ones by light the library
does not hold (*out-of-library*) — in validation colour-science's
fluorescent and high-intensity-discharge light sources, in test its LED and phosphor light sources, LED spectra
synthesised with ``colour.sd_multi_leds`` and blackbodies at temperatures away from the library's. Light sources equal to a
library member within 0.02 (max absolute difference, both at peak 1: SA, SC, incandescent) count as library
members.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["reflectances", "synthetic_reflectance", "spectral_distance", "scene_illuminant", "light_kind",
           "val_lights", "test_lights", "on_bands", "DUPLICATE", "REFLECTANCE_FAMILIES", "SPLIT_RANK", "MAX_DRAWS"]

DUPLICATE = 0.035  # the median difference of two measurements of one ColorChecker patch (N Ohta, BabelColor)
SPLIT_RANK = ("test", "val", "train")  # a spectrum in an earlier split is removed from the later ones
REFLECTANCE_FAMILIES = {
    # the PMC chart re-measures ColorChecker patches (Bluish Green, Blue Sky, Cyan, the neutrals …): with them
    "test": (("colourchecker", "ColorChecker N Ohta"), ("colourchecker", "ISO 17321-1"),
             ("colourchecker", "BabelColor Average"), ("colourchecker", "babel_average"),
             ("colourchecker", "cc_ohta"), ("colourchecker", "PMC")),
    "val": (("vs", "NIST CQS 9.0"), ("vs", "NIST CQS 7.4")),
    "train": (("tcs", "CIE 1995"), ("tcs", "CIE 2024")),
}
MAX_DRAWS = 10_000  # a synthetic reflectance drawn this often next to a held-out one is an error, not a loop
# colour-science light sources by family (substrings of their names)
_VAL_LIGHTS = ("FL", "F32T8", "F34", "F40", "T8 ", "TL-84", "Kolor", "HPS", "LPS", "Mercury", "Metal Halide", "H38",
               "MHC100", "SDW-T", "Natural")
_TEST_LIGHTS = ("LED", "PHOS", "Luxeon", "Kinoton", "Neodimium")


def on_bands(sd) -> np.ndarray:
    """A colour-science spectral distribution on the 31 bands 400–700 nm (10 nm)."""
    import colour

    return np.asarray(sd.copy().align(colour.SpectralShape(400, 700, 10)).values, np.float64)


def _collection(kind: str, name: str):
    from colour.characterisation import SDS_COLOURCHECKERS
    from colour.quality import SDS_TCS, SDS_VS

    return {"colourchecker": SDS_COLOURCHECKERS, "tcs": SDS_TCS, "vs": SDS_VS}[kind].get(name, {})


def spectral_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Max absolute difference on the bands after the least-squares scale of each onto the other (the larger):
    a scene multiplies a reflectance by shading and exposure, so a scaled copy is the same surface."""
    def one(x, y):
        return float(np.abs(x - (x @ y) / max(float(y @ y), 1e-12) * y).max())
    return max(one(a, b), one(b, a))


def _distances(many: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``spectral_distance`` of ``r`` to every row of ``many`` [N, 31], at once."""
    dots = many @ r
    a = np.abs(r[None] - (dots / np.maximum((many * many).sum(axis=1), 1e-12))[:, None] * many).max(axis=1)
    b = np.abs(many - (dots / max(float(r @ r), 1e-12))[:, None] * r[None]).max(axis=1)
    return np.maximum(a, b)


def _unique_against(rows: list[np.ndarray], taken: list[np.ndarray]) -> list[np.ndarray]:
    """``rows`` without those within DUPLICATE (``spectral_distance``) of one in ``taken`` or of an earlier one
    of ``rows``."""
    out: list[np.ndarray] = []
    for r in rows:
        if all(spectral_distance(r, t) > DUPLICATE for t in (*taken, *out)):
            out.append(r)
    return out


@functools.lru_cache(maxsize=None)
def _measured() -> dict:
    taken: list[np.ndarray] = []
    out = {}
    for split in SPLIT_RANK:
        rows = [np.clip(on_bands(sd), 0, 1) for kind, name in REFLECTANCE_FAMILIES[split]
                for sd in _collection(kind, name).values()]
        out[split] = _unique_against(rows, taken)
        taken += out[split]
    return {k: np.array(v) for k, v in out.items()}


def reflectances(split: str) -> np.ndarray:
    """[R, 31] the measured reflectances of a split (families and deduplication in the module docstring)."""
    return _measured()[split].copy()


def synthetic_reflectance(rng: np.random.Generator) -> np.ndarray:
    """[31] a smooth random reflectance in [0.02, 0.95]: a level plus two to four logistic steps and bumps; a
    draw within ``DUPLICATE`` of a held-out (validation or test) reflectance is drawn again."""
    held = _held_out()
    for _ in range(MAX_DRAWS):
        r = _smooth_draw(rng)
        if _distances(held, r).min() > DUPLICATE:
            return r
    from doefab.errors import DoefabError

    raise DoefabError(f"no synthetic reflectance away from the held-out ones in {MAX_DRAWS} draws")


def _smooth_draw(rng: np.random.Generator) -> np.ndarray:
    lam = np.linspace(400, 700, 31)
    r = np.full(31, rng.uniform(0.05, 0.5))
    for _ in range(int(rng.integers(2, 5))):
        c, w, a = rng.uniform(380, 720), rng.uniform(15, 80), rng.uniform(-0.5, 0.5)
        r += a / (1 + np.exp(-(lam - c) / w)) if rng.random() < 0.5 else a * np.exp(-0.5 * ((lam - c) / w) ** 2)
    return np.clip(r, 0.02, 0.95)


@functools.lru_cache(maxsize=None)
def _held_out() -> np.ndarray:
    return np.concatenate([_measured()["val"], _measured()["test"]])


@functools.lru_cache(maxsize=None)
def _light_sources() -> tuple[dict, dict]:
    """({name: spectrum}, {name: spectrum}): colour-science's light sources of the validation and of the test
    families, peak 1, those equal to a library member left out."""
    import colour

    from doefab.reconstruction.illuminant import illuminant_library

    lib = illuminant_library()
    val, test = {}, {}
    for name, sd in colour.SDS_LIGHT_SOURCES.items():
        e = on_bands(sd)
        if not np.all(np.isfinite(e)) or e.max() <= 0:
            continue
        e = e / e.max()
        if np.abs(lib - e).max(axis=1).min() <= 0.02:
            continue  # a library member under another name
        if any(k in name for k in _TEST_LIGHTS):
            test[name] = e
        elif any(k in name for k in _VAL_LIGHTS):
            val[name] = e
    return val, test


def val_lights() -> np.ndarray:
    return np.array(list(_light_sources()[0].values()))


def test_lights() -> np.ndarray:
    return np.array(list(_light_sources()[1].values()))


def _synthetic_light(rng: np.random.Generator) -> np.ndarray:
    """An LED mix (``colour.sd_multi_leds``) or a blackbody away from the library's 2856 K."""
    import colour

    if rng.random() < 2 / 3:
        n = int(rng.integers(2, 5))
        sd = colour.sd_multi_leds(np.sort(rng.uniform(430, 650, n)), half_spectral_widths=rng.uniform(10, 45, n),
                                  peak_power_ratios=rng.uniform(0.3, 1.0, n))
    else:
        t = rng.uniform(2000, 2600) if rng.random() < 0.5 else rng.uniform(3200, 9500)
        sd = colour.sd_blackbody(float(t))
    e = on_bands(sd)
    return e / e.max()


def light_kind(split: str, index: int) -> str:
    """"in-library" or "out-of-library": whether scene ``index`` of ``split`` is lit by a library member."""
    if split == "train":
        return "in-library"
    return "in-library" if index % 2 == 0 else "out-of-library"


def scene_illuminant(rng: np.random.Generator, split: str, kind: str) -> np.ndarray:
    """[31] the light of one scene, peak 1 (see the module docstring)."""
    from doefab.reconstruction.illuminant import illuminant_library

    if kind == "in-library":
        lib = illuminant_library()
        return lib[rng.integers(len(lib))]
    if split == "val":
        v = val_lights()
        return v[rng.integers(len(v))]
    if rng.random() < 0.3:
        t = test_lights()
        return t[rng.integers(len(t))]
    return _synthetic_light(rng)
