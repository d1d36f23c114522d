"""Training, validation and test never share content: photographs, reflectance spectra, light (issue 23)."""

import hashlib
from itertools import combinations

import numpy as np
import pytest

from doefab.reconstruction import spectra
from doefab.reconstruction.data import IMAGES, split_images
from doefab.reconstruction.illuminant import illuminant_library

SPLITS = ("train", "val", "test")


def _thumb(img: np.ndarray) -> np.ndarray:
    """A 32 × 32 grey thumbnail, zero mean, unit norm (catches a crop or a resize of the same picture)."""
    g = img.mean(axis=2)
    h, w = g.shape
    s = min(h, w)
    g = g[(h - s) // 2:(h - s) // 2 + s, (w - s) // 2:(w - s) // 2 + s]
    k = s // 32
    t = g[:k * 32, :k * 32].reshape(32, k, 32, k).mean(axis=(1, 3))
    t = t - t.mean()
    return t / (np.linalg.norm(t) + 1e-12)


@pytest.mark.parametrize("a, b", list(combinations(SPLITS, 2)))
def test_photographs_belong_to_one_split(a, b):
    assert not set(IMAGES[a]) & set(IMAGES[b])
    ia, ib = split_images(a), split_images(b)
    ha = {hashlib.sha256(x.tobytes()).hexdigest() for x in ia}
    hb = {hashlib.sha256(x.tobytes()).hexdigest() for x in ib}
    assert not ha & hb
    corr = max(float((_thumb(x) * _thumb(y)).sum()) for x in ia for y in ib)
    assert corr < 0.9, f"a {a} photograph looks like a {b} one (thumbnail correlation {corr:.3f})"


@pytest.mark.parametrize("a, b", list(combinations(SPLITS, 2)))
def test_measured_reflectances_belong_to_one_split(a, b):
    ra, rb = spectra.reflectances(a), spectra.reflectances(b)
    gap = min(spectra.spectral_distance(x, y) for x in ra for y in rb)
    assert gap > spectra.DUPLICATE, f"{a} and {b} share a reflectance (closest pair differs by {gap:.2g})"
    raw = np.abs(ra[:, None] - rb[None]).max(axis=-1).min()
    assert raw > spectra.DUPLICATE  # unscaled too


def test_the_colourchecker_collections_collapse_to_one_family_in_test():
    """ISO 17321-1 is the N Ohta measurement to 1e-6: it must not survive as a second copy anywhere."""
    test = spectra.reflectances("test")
    d = np.abs(test[:, None] - test[None]).max(axis=-1) + np.eye(len(test))
    assert d.min() > spectra.DUPLICATE and 24 <= len(test) < 24 * 5


def test_synthetic_training_reflectances_are_not_held_out_ones():
    rng = np.random.default_rng(123)
    syn = np.array([spectra.synthetic_reflectance(rng) for _ in range(2000)])
    for split in ("val", "test"):
        held = spectra.reflectances(split)
        assert min(spectra.spectral_distance(x, h) for x in syn[:300] for h in held) > spectra.DUPLICATE
        assert np.abs(syn[:, None] - held[None]).max(axis=-1).min() > spectra.DUPLICATE


def test_the_spectral_distance_ignores_scale_and_is_symmetric():
    a = 0.2 + 0.6 * np.linspace(0, 1, 31)
    assert spectra.spectral_distance(a, 0.6 * a) < 1e-12  # shading and exposure scale a surface
    b = a.copy()
    b[10] += 0.1
    assert spectra.spectral_distance(a, b) == pytest.approx(spectra.spectral_distance(b, a))
    assert spectra.spectral_distance(a, b) > 0.05


def test_out_of_library_light_is_not_in_the_library_and_test_light_not_in_validation():
    lib = illuminant_library()
    val, test = spectra.val_lights(), spectra.test_lights()
    rng = np.random.default_rng(7)
    made = np.array([spectra.scene_illuminant(rng, "test", "out-of-library") for _ in range(200)])
    for lights in (val, test, made):
        assert np.abs(lights[:, None] - lib[None]).max(axis=-1).min() > 0.02
    assert np.abs(test[:, None] - val[None]).max(axis=-1).min() > 0.02
    assert len(val) >= 10 and len(test) >= 5


def test_light_kinds_alternate_in_held_out_splits_and_training_uses_the_library():
    assert {spectra.light_kind("train", i) for i in range(10)} == {"in-library"}
    for split in ("val", "test"):
        kinds = [spectra.light_kind(split, i) for i in range(6)]
        assert kinds == ["in-library", "out-of-library"] * 3


def test_the_duplicate_tolerance_covers_two_measurements_of_one_surface():
    """Two measurements of the same ColorChecker patch (colour-science's N Ohta and BabelColor average) differ by
    a median 0.03 on the 31 bands: the tolerance that decides "same content" must be at least that, or a second
    measurement of a test patch in another collection (the PMC chart's Cyan, Gray-50, Black …) passes as new."""
    from colour.characterisation import SDS_COLOURCHECKERS

    ohta, babel = SDS_COLOURCHECKERS["ColorChecker N Ohta"], SDS_COLOURCHECKERS["BabelColor Average"]
    same = [np.abs(np.clip(spectra.on_bands(ohta[n]), 0, 1) - np.clip(spectra.on_bands(babel[n]), 0, 1)).max()
            for n in ohta]
    assert spectra.DUPLICATE >= np.median(same) > 0.01
    # the PMC chart re-measures ColorChecker patches: no PMC spectrum may train a network the test split scores
    train = spectra.reflectances("train")
    for name, sd in SDS_COLOURCHECKERS["PMC"].items():
        p = np.clip(spectra.on_bands(sd), 0, 1)
        assert min(spectra.spectral_distance(p, t) for t in train) > spectra.DUPLICATE, name
    # and no training spectrum lies as close to a test one as two measurements of one patch typically do
    test = spectra.reflectances("test")
    assert min(np.abs(t - x).max() for t in train for x in test) > np.median(same)
