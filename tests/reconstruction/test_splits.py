"""Training, validation and test never share content: photographs, reflectance spectra, light (issue 23)."""

import hashlib
from itertools import combinations

import numpy as np
import pytest

from doefab.reconstruction import spectra
from doefab.reconstruction.data import IMAGES, split_images
from doefab.reconstruction.illuminant import illuminant_library

SPLITS = ("train", "val", "test")
SIDE = 256  # pixels on a photograph's long side where its features are found, whatever its size
MATCHED = 8  # ORB matches one similarity maps within 2 px: 18 or more for a crop, shift or rescale of one of the
# photographs (the controls below), at most 2 for two different ones


def _features(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ORB keypoints (row, column) and descriptors of a photograph's grey picture resized to ``SIDE`` pixels on its
    long side (so a rescaled copy looks like the original, and a crop like an enlargement of part of it)."""
    from skimage.feature import ORB
    from skimage.transform import rescale

    g = img.mean(axis=2) ** (1 / 2.2)
    f = SIDE / max(g.shape)
    orb = ORB(n_keypoints=500, fast_threshold=0.01)
    orb.detect_and_extract(rescale(g, f, anti_aliasing=f < 1))
    return orb.keypoints, orb.descriptors


def _matched(fa, fb) -> int:
    """How many of two photographs' ORB matches one similarity (shift, rotation, scale) maps onto each other
    within 2 px (RANSAC): a crop, shift or rescale of one picture keeps many, two pictures none but by chance."""
    import warnings

    from skimage.feature import match_descriptors
    from skimage.measure import ransac
    from skimage.transform import SimilarityTransform

    (ka, da), (kb, db) = fa, fb
    m = match_descriptors(da, db, cross_check=True, max_ratio=0.8)
    if len(m) < 3:
        return len(m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "no inliers found": two different pictures
        _, inliers = ransac((ka[m[:, 0], ::-1], kb[m[:, 1], ::-1]), SimilarityTransform, min_samples=3,
                            residual_threshold=2, max_trials=300, rng=0)
    return 0 if inliers is None else int(inliers.sum())


@pytest.fixture(scope="module")
def photographs():
    """{split: [(name, photograph, its ORB features)]}."""
    return {s: [(n, x, _features(x)) for n, x in zip(IMAGES[s], split_images(s))] for s in SPLITS}


def test_a_crop_shift_or_rescale_of_every_photograph_is_recognised(photographs):
    """The near-duplicate check finds each photograph in a copy of it shifted by an eighth of its short side
    (60 px of 512) and rescaled ×0.5, and in its central crop keeping 3/4 of each side — copies that a 32 × 32
    grey thumbnail's correlation with the original's scores between −0.17 and 0.92 (all but one under 0.9)."""
    from skimage.transform import rescale

    for name, x, f in (p for split in photographs.values() for p in split):
        s = round(min(x.shape[:2]) / 8)
        h, w = x.shape[:2]
        copies = {"shifted, ×0.5": rescale(x[s:, s:], 0.5, anti_aliasing=True, channel_axis=2),
                  "cropped to 3/4": x[h // 8:h - h // 8, w // 8:w - w // 8]}
        for how, copy in copies.items():
            assert _matched(f, _features(copy)) >= MATCHED, f"{name} {how} not recognised"


@pytest.mark.parametrize("a, b", list(combinations(SPLITS, 2)))
def test_photographs_belong_to_one_split(a, b, photographs):
    """No photograph of one split is another's by name, by bytes or as a crop, shift or rescale of it."""
    assert not set(IMAGES[a]) & set(IMAGES[b])
    ha = {hashlib.sha256(x.tobytes()).hexdigest() for _, x, _ in photographs[a]}
    hb = {hashlib.sha256(x.tobytes()).hexdigest() for _, x, _ in photographs[b]}
    assert not ha & hb
    pairs = {(na, nb): _matched(fa, fb) for na, _, fa in photographs[a] for nb, _, fb in photographs[b]}
    alike = {k: v for k, v in pairs.items() if v >= MATCHED}
    assert not alike, f"{a} and {b} photographs that are one picture (matches): {alike}"


def test_a_surface_measured_in_two_splits_families_stays_in_the_earlier_split_only():
    """Known re-measurements across the families: CIE TCS09 (strong red) and NIST CQS 9.0 VS1 (= CQS 7.4 VS14) lie
    0.016–0.032 from the ColorChecker's red patch (test) after a scale — copies within ``COPY`` — so neither
    validation nor training holds them, while test keeps its red, validation the CQS samples the test split does
    not hold (VS5) and training the CIE samples (TCS01)."""
    from colour.characterisation import SDS_COLOURCHECKERS
    from colour.quality import SDS_TCS, SDS_VS

    def held(split, sd):
        return bool((np.abs(spectra.reflectances(split) - np.clip(spectra.on_bands(sd), 0, 1)).max(axis=1) < 1e-9)
                    .any())

    red = SDS_COLOURCHECKERS["ColorChecker N Ohta"]["red"]
    twins = [SDS_TCS["CIE 1995"]["TCS09"], SDS_TCS["CIE 2024"]["TCS09"], SDS_VS["NIST CQS 9.0"]["VS1"],
             SDS_VS["NIST CQS 7.4"]["VS14"]]
    red31 = np.clip(spectra.on_bands(red), 0, 1)
    assert all(spectra.spectral_distance(red31, np.clip(spectra.on_bands(t), 0, 1)) < spectra.COPY for t in twins)
    assert held("test", red) and [(held("val", t), held("train", t)) for t in twins] == [(False, False)] * 4
    assert held("val", SDS_VS["NIST CQS 9.0"]["VS5"]) and held("train", SDS_TCS["CIE 1995"]["TCS01"])


def test_a_synthetic_draw_next_to_a_held_out_reflectance_is_drawn_again(monkeypatch):
    """A training reflectance drawn within ``COPY`` of a held-out one (here: the test split's red patch
    itself, then one 0.02 off it) is replaced by the next draw that is not; one that never comes is refused."""
    from colour.characterisation import SDS_COLOURCHECKERS

    from doefab.errors import DoefabError

    red = np.clip(spectra.on_bands(SDS_COLOURCHECKERS["ColorChecker N Ohta"]["red"]), 0, 1)
    ramp = np.linspace(0.95, 0.02, 31)  # 0.30 from every held-out reflectance
    draws = iter([red, red + 0.02, ramp])
    monkeypatch.setattr(spectra, "_smooth_draw", lambda rng: next(draws))
    assert np.array_equal(spectra.synthetic_reflectance(np.random.default_rng(0)), ramp)
    monkeypatch.setattr(spectra, "_smooth_draw", lambda rng: red)
    monkeypatch.setattr(spectra, "MAX_DRAWS", 5)
    with pytest.raises(DoefabError, match="5 draws"):
        spectra.synthetic_reflectance(np.random.default_rng(0))


def test_the_colourchecker_collections_collapse_to_one_family_in_test():
    """ISO 17321-1 is the N Ohta measurement to 1e-6: it must not survive as a second copy anywhere."""
    test = spectra.reflectances("test")
    d = np.abs(test[:, None] - test[None]).max(axis=-1) + np.eye(len(test))
    assert d.min() > spectra.COPY and 24 <= len(test) < 24 * 5


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


def _lit_by(monkeypatch, split: str, scenes: int) -> np.ndarray:
    """[scenes, 31] the light of each of ``split``'s first scenes, as the scenes are drawn (``light_kind``)."""
    from doefab.reconstruction.data import sample_rng, spectral_sample

    seen, draw = [], spectra.scene_illuminant
    monkeypatch.setattr(spectra, "scene_illuminant", lambda *a: seen.append(draw(*a)) or seen[-1])
    for i in range(scenes):
        spectral_sample(sample_rng(split, i), 32, split, spectra.light_kind(split, i))
    return np.array(seen)


def test_no_held_out_scene_is_lit_by_a_light_training_uses(monkeypatch):
    """Training scenes are lit by the illuminant library's members, every validation and test scene by light
    farther than 0.02 (at peak 1) from each of them."""
    lib = illuminant_library()
    train = _lit_by(monkeypatch, "train", 6)
    assert np.abs(train[:, None] - lib[None]).max(axis=-1).min(axis=1).max() < 1e-12
    for split in ("val", "test"):
        assert {spectra.light_kind(split, i) for i in range(12)} == {"out-of-library"}
        lights = _lit_by(monkeypatch, split, 12)
        assert len(lights) == 12 and np.abs(lights[:, None] - lib[None]).max(axis=-1).min() > 0.02, split


def test_a_scene_light_of_another_split_is_refused():
    """Library light for a held-out scene, held-out light for a training scene, or a split without scenes is
    one refusal naming the split, the light and the kinds that work; so is a reflectance split or step."""
    from doefab.errors import DoefabError

    rng = np.random.default_rng(0)
    for split, kind in (("test", "in-library"), ("val", "in-library"), ("train", "out-of-library"),
                        ("holdout", None)):
        with pytest.raises(DoefabError, match=f"split '{split}'.*'out-of-library'"):
            spectra.scene_illuminant(rng, split, kind)
    for split, step in (("holdout", 2), ("test", 3)):
        with pytest.raises(DoefabError, match=f"split '{split}' after step {step}.*step 2"):
            spectra.reflectances(split, step)


def _gap(x: np.ndarray, y: np.ndarray) -> float:
    """Max absolute difference after the least-squares scale of each spectrum onto the other (the larger),
    by ``numpy.linalg.lstsq``: the distance ``spectra.spectral_distance`` computes, computed apart from it."""
    def one(a, b):
        return float(np.abs(a - np.linalg.lstsq(b[:, None], a, rcond=None)[0][0] * b).max())
    return max(one(x, y), one(y, x))


def test_the_one_surface_tolerance_covers_every_two_measurements_of_one_patch():
    """Two measurements of one ColorChecker patch (colour-science's N Ohta and BabelColor Average) differ by up
    to 0.129 after a scale (foliage; 95th percentile 0.120): ``DUPLICATE`` is at least the largest, and no
    validation or test reflectance lies within it of a training one — e.g. BabelColor's yellow, 0.046 from
    CIE TCS10, is not in test, nor any PMC patch that close to a training sample."""
    from colour.characterisation import SDS_COLOURCHECKERS

    def bands(sd):
        return np.clip(spectra.on_bands(sd), 0, 1)

    ohta, babel = SDS_COLOURCHECKERS["ColorChecker N Ohta"], SDS_COLOURCHECKERS["BabelColor Average"]
    same = np.array([_gap(bands(ohta[n]), bands(babel[n])) for n in ohta])
    assert np.percentile(same, 95) <= same.max() <= spectra.DUPLICATE <= 1.1 * same.max()
    assert np.median(same) < spectra.COPY < np.percentile(same, 95)
    train = spectra.reflectances("train")
    for split in ("val", "test"):
        held = spectra.reflectances(split)
        assert min(_gap(t, x) for t in train for x in held) > spectra.DUPLICATE, split
        assert len(held) >= 12, split
    yellow = bands(babel["yellow"])
    assert _gap(yellow, bands(ohta["yellow"])) < spectra.DUPLICATE  # a second measurement of one patch
    assert "BabelColor Average yellow" not in spectra.reflectance_names("test")
    assert "BabelColor Average yellow" in spectra.reflectance_names("test", step=1)
    test = spectra.reflectances("test")
    for name, sd in SDS_COLOURCHECKERS["PMC"].items():
        p = bands(sd)
        if min(_gap(p, t) for t in train) <= spectra.DUPLICATE:
            assert np.abs(test - p).max(axis=1).min() > 1e-9, name


def test_the_training_reflectances_are_those_the_shipped_networks_were_trained_on(monkeypatch):
    """Only validation and test lose spectra to ``DUPLICATE``: training keeps the 14 CIE samples, and a
    synthetic training draw is still drawn again when it copies a spectrum dropped from test (BabelColor's
    yellow), so the training scenes stay those the shipped networks saw."""
    from colour.characterisation import SDS_COLOURCHECKERS
    from colour.quality import SDS_TCS

    names = [f"CIE 1995 TCS{i:02d}" for i in (1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 12, 13, 14)] + ["CIE 2024 TCS15"]
    assert list(spectra.reflectance_names("train")) == names
    want = [np.clip(spectra.on_bands(SDS_TCS[n[:8]][n[9:]]), 0, 1) for n in names]
    np.testing.assert_array_equal(spectra.reflectances("train"), np.array(want))
    yellow = np.clip(spectra.on_bands(SDS_COLOURCHECKERS["BabelColor Average"]["yellow"]), 0, 1)
    ramp = np.linspace(0.95, 0.02, 31)
    draws = iter([yellow, ramp])
    monkeypatch.setattr(spectra, "_smooth_draw", lambda rng: next(draws))
    assert np.array_equal(spectra.synthetic_reflectance(np.random.default_rng(0)), ramp)


def test_the_measured_sets_photographs_are_no_training_photograph(photographs):
    """The measured-data validation set (``realdata``): no HDR radiance map is a photograph of any split, and the
    depth scene's image is none of training or test (it is one of the validation split's photographs), as a
    crop, shift or rescale of one (their tone-mapped pictures against each photograph)."""
    from skimage.data import stereo_motorcycle

    from doefab.reconstruction.realdata import _hdr_maps

    measured = [m / max(float(np.quantile(m, 0.99)), 1e-6) for m in _hdr_maps()]
    measured = [np.clip(m, 0, 1) for m in measured] + [(stereo_motorcycle()[0] / 255.0) ** 2.2]
    feats = [_features(m) for m in measured]
    pairs = {(i, split, n): _matched(f, ft) for i, f in enumerate(feats) for split in SPLITS
             for n, _, ft in photographs[split] if not (i == len(feats) - 1 and split == "val")}
    assert not {k: v for k, v in pairs.items() if v >= MATCHED}
    assert _matched(feats[-1], dict((n, f) for n, _, f in photographs["val"])["stereo_motorcycle"]) >= MATCHED
    # the check sees a measured picture in itself shifted and rescaled
    from skimage.transform import rescale

    s = round(min(measured[0].shape[:2]) / 8)
    assert _matched(feats[0], _features(rescale(measured[0][s:, s:], 0.5, anti_aliasing=True,
                                                channel_axis=2))) >= MATCHED
