"""Reflectances and illuminants of the hyperspectral scenes, split by content and open to light outside the
library the proposed network searches.

**Reflectances.** colour-science ships overlapping collections: the ISO 17321-1 chart is the ColorChecker N
Ohta measurement to 1e-6, the PMC chart re-measures ColorChecker patches, CIE 2024 repeats 14 of CIE 1995's
samples and NIST CQS 7.4 eight of CQS 9.0's. Each split takes whole families: test the ColorChecker (every
measurement of it) and the PMC chart, validation the NIST CQS samples, training the CIE test colour samples.
Distances are ``spectral_distance``: the max absolute difference on the 31 bands after a least-squares scale, as
shading and exposure scale a surface. Two steps:

1. copies (``COPY``, 0.035): a spectrum within 0.035 of one in an earlier-ranked split (test, then validation)
   is dropped from the later one, and from its own split when it repeats one there. This fixes the training
   set, the 14 CIE samples the shipped networks were trained on.
2. one surface (``DUPLICATE``, 0.13): every validation or test spectrum within 0.13 of a training one is
   dropped. 0.13 is the upper end of the gaps between colour-science's two measurements of one ColorChecker
   patch (N Ohta and BabelColor: median 0.031, 95th percentile 0.120, largest 0.129, foliage), so no second
   measurement of a training surface passes as a held-out one. Validation and test stay apart by ``COPY``
   only: at 0.13, 13 of the 15 validation spectra would have a test neighbour.

``benchmarks/results/spectra_nearest_pairs.md`` lists the nearest pairs between splits. Training also draws
smooth synthetic reflectances, so the networks do not learn a dozen spectra. A draw within ``COPY`` of a spectrum
of the validation or test families (step 1) is drawn again, the rule the shipped networks were trained under.

**Illuminants.** The proposed network searches a library (``doefab/weights/illuminants.csv``: colour-science's
CIE illuminants). Training scenes are lit by library members only; validation and test scenes only by light the
library does not hold (*out-of-library*, ``light_kind``): in validation colour-science's fluorescent and
high-intensity-discharge light sources, in test its LED and phosphor light sources, LED spectra synthesised
with ``colour.sd_multi_leds`` and blackbodies at temperatures away from the library's. Light sources equal to a
library member within 0.02 (max absolute difference, both at peak 1: SA, SC, incandescent) count as library
members. So no held-out scene is lit by a light any training scene is lit by; the library does hold lamps of
the same kinds (CIE fluorescent, high-pressure discharge and LED illuminants).
"""

from __future__ import annotations

import functools

import numpy as np

from doefab.reconstruction.bands import on_bands

__all__ = ["reflectances", "reflectance_names", "synthetic_reflectance", "spectral_distance", "scene_illuminant",
           "light_kind", "held_out_light_sources", "val_lights", "test_lights", "on_bands", "COPY", "DUPLICATE",
           "REFLECTANCE_FAMILIES", "SPLIT_RANK", "MAX_DRAWS"]

COPY = 0.035  # one spectrum in two collections or twice in one (ISO 17321-1 is N Ohta to 1e-6); fixes training
DUPLICATE = 0.13  # ≥ every gap between two measurements of one ColorChecker patch (N Ohta, BabelColor: ≤ 0.129)
SPLIT_RANK = ("test", "val", "train")  # within COPY, a spectrum in an earlier split is removed from the later ones
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


def _unique_against(rows: list[tuple[str, np.ndarray]], taken: list[np.ndarray]) -> list[tuple[str, np.ndarray]]:
    """``rows`` (name, spectrum) without those within ``COPY`` of one in ``taken`` or of an earlier one of
    ``rows``."""
    out: list[tuple[str, np.ndarray]] = []
    for name, r in rows:
        if all(spectral_distance(r, t) > COPY for t in (*taken, *(x for _, x in out))):
            out.append((name, r))
    return out


@functools.lru_cache(maxsize=None)
def _families() -> dict:
    """{split: [(name, spectrum)]}: each split's families without copies (step 1 of the module docstring)."""
    taken: list[np.ndarray] = []
    out = {}
    for split in SPLIT_RANK:
        rows = [(f"{name} {patch}", np.clip(on_bands(sd), 0, 1)) for kind, name in REFLECTANCE_FAMILIES[split]
                for patch, sd in _collection(kind, name).items()]
        out[split] = _unique_against(rows, taken)
        taken += [r for _, r in out[split]]
    return out


@functools.lru_cache(maxsize=None)
def _measured() -> dict:
    """{split: [(name, spectrum)]}: ``_families`` less every held-out spectrum within ``DUPLICATE`` of a training
    one (step 2)."""
    fam = _families()
    train = np.array([r for _, r in fam["train"]])
    return {"train": fam["train"], **{s: [(n, r) for n, r in fam[s] if _distances(train, r).min() > DUPLICATE]
                                      for s in ("val", "test")}}


def _split(split: str, step: int) -> list[tuple[str, np.ndarray]]:
    if split not in SPLIT_RANK or step not in (1, 2):
        from doefab.errors import DoefabError

        raise DoefabError(f"reflectances of split {split!r} after step {step!r}: give a split of "
                          f"{', '.join(SPLIT_RANK)} and step 2 (the splits the scenes use) or 1 (copies removed only)")
    return (_families() if step == 1 else _measured())[split]


def reflectances(split: str, step: int = 2) -> np.ndarray:
    """[R, 31] the measured reflectances of a split: after both steps of the module docstring (the scenes'), or
    with ``step=1`` after the first only."""
    return np.array([r for _, r in _split(split, step)])


def reflectance_names(split: str, step: int = 2) -> tuple[str, ...]:
    """The collection and patch of each row of ``reflectances(split, step)``, e.g. "CIE 1995 TCS10"."""
    return tuple(n for n, _ in _split(split, step))


def synthetic_reflectance(rng: np.random.Generator) -> np.ndarray:
    """[31] a smooth random reflectance in [0.02, 0.95]: a level plus two to four logistic steps and bumps; a
    draw within ``COPY`` of a spectrum of the validation or test families is drawn again."""
    held = _held_out()
    for _ in range(MAX_DRAWS):
        r = _smooth_draw(rng)
        if _distances(held, r).min() > COPY:
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
    """The validation and test families' spectra after step 1, which synthetic training draws keep away from."""
    return np.concatenate([reflectances("val", 1), reflectances("test", 1)])


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


def held_out_light_sources() -> tuple[dict, dict]:
    """({name: [31] spectrum}, {name: spectrum}): the measured light sources of validation and of test, peak 1."""
    return tuple(dict(d) for d in _light_sources())


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


def light_kind(split: str, index: int = 0) -> str:
    """"in-library" for every training scene, "out-of-library" for every other (``index``: any, all of a split's
    scenes are lit alike): no held-out scene is lit by a light any training scene is lit by."""
    return "in-library" if split == "train" else "out-of-library"


def scene_illuminant(rng: np.random.Generator, split: str, kind: str | None = None) -> np.ndarray:
    """[31] the light of one scene of ``split``, peak 1 (see the module docstring); ``kind``, when given, must
    be the split's (``light_kind``)."""
    from doefab.errors import DoefabError
    from doefab.reconstruction.illuminant import illuminant_library

    want = light_kind(split)
    if split not in SPLIT_RANK or kind not in (None, want):
        fix = f"give kind {want!r} or None" if split in SPLIT_RANK else f"give a split of {', '.join(SPLIT_RANK)}"
        raise DoefabError(f"scene light {kind!r} for split {split!r}: training scenes are lit by the library "
                          f"('in-library'), validation and test scenes by light outside it ('out-of-library'); {fix}")
    if want == "in-library":
        lib = illuminant_library()
        return lib[rng.integers(len(lib))]
    if split == "val":
        v = val_lights()
        return v[rng.integers(len(v))]
    if rng.random() < 0.3:
        t = test_lights()
        return t[rng.integers(len(t))]
    return _synthetic_light(rng)
