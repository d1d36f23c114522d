"""The measured-data validation set (split ``real``): its scenes, its light, and that training never draws it."""

import numpy as np
import pytest

from doefab.reconstruction import realdata


def test_depth_is_the_published_calibration_of_the_measured_disparity():
    """Z = f·B / (d + doffs) with the calibration skimage's docstring gives for its quarter-resolution Motorcycle,
    computed here at every measured pixel; each unmeasured pixel holds the depth of a measured pixel at the
    nearest distance (brute force on a sample of them)."""
    from skimage.data import stereo_motorcycle

    _, _, disp = stereo_motorcycle()
    img, depth, known = realdata._motorcycle()
    assert np.array_equal(known, np.isfinite(disp)) and 0.05 < 1 - known.mean() < 0.1
    z = 994.978 * 0.193001 / (disp[known] + 31.086)
    assert np.allclose(depth[known], z, rtol=1e-6)
    assert 2.0 < z.min() and z.max() < 5.1  # inside the shipped design's 1–5 m (to its far plane's clip)
    ky, kx = np.nonzero(known)
    rng = np.random.default_rng(0)
    uy, ux = np.nonzero(~known)
    for i in rng.choice(len(uy), 20, replace=False):
        d2 = (ky - uy[i]) ** 2 + (kx - ux[i]) ** 2
        nearest = depth[ky[d2 == d2.min()], kx[d2 == d2.min()]]
        assert np.isclose(depth[uy[i], ux[i]], nearest, rtol=1e-6).any()


def test_a_depth_sample_is_a_crop_clipped_to_the_planes():
    scene, depth, known = realdata.depth_real_sample(np.random.default_rng(3), 120, 2.8, 3.2)
    assert scene.shape == (3, 120, 120) and depth.shape == known.shape == (120, 120)
    assert depth.min() == np.float32(2.8) and depth.max() == np.float32(3.2)
    with pytest.raises(Exception, match="smaller --size"):
        realdata.depth_real_sample(np.random.default_rng(3), 600, 1.0, 5.0)


def test_hdr_exposure_clips_one_to_five_percent_and_keeps_the_maps_contrast():
    """Each draw: 1–5 % of pixels above the half-exposure clip (2.0) where the crop's range allows it (one pixel
    of slack for quantile ties), nothing above 2^8, and below the cap the crop is the map times one gain."""
    rng = np.random.default_rng(1)
    maps = realdata._hdr_maps()
    for _ in range(12):
        s = realdata.hdr_real_sample(rng, 150)
        assert s.shape == (3, 150, 150) and s.max() <= 256.0 and s.min() >= 0.0
        above = (s.max(axis=0) > 2.0).mean()
        assert above <= 0.05 + 1 / 150**2
        assert above >= 0.01 - 1 / 150**2 or s.max() < 2.0 + 1e-3
    # the stored maps hold real dynamic range: at least three of them span over 2^8 between median and peak
    spans = [float(m.max() / max(np.median(m), 1e-9)) for m in maps]
    assert sum(x > 256 for x in spans) >= 3


def test_real_light_is_no_library_no_validation_and_no_test_light():
    """Every draw lies ≥ 0.1 (max abs, peak 1) from each library member and each measured light of the
    validation and test families; the lamps left out lie within 0.02 of the library's illuminant A."""
    import colour

    from doefab.reconstruction.bands import on_bands
    from doefab.reconstruction.illuminant import illuminant_library
    from doefab.reconstruction.spectra import test_lights, val_lights

    others = np.concatenate([illuminant_library(), val_lights(), test_lights()])
    rng = np.random.default_rng(2)
    for _ in range(100):
        e = realdata.real_light(rng)
        assert e.shape == (31,) and np.isclose(e.max(), 1.0)
        assert np.abs(others - e).max(axis=1).min() > 0.1
    a = on_bands(colour.SDS_LIGHT_SOURCES["Incandescent"])
    assert np.abs(illuminant_library() - a / a.max()).max(axis=1).min() < 0.02


def test_training_never_draws_the_measured_set(monkeypatch):
    """Training batches of every task made with the measured samplers replaced by ones that fail: none is called;
    the same replacement makes a real-split batch fail (the spy works)."""
    from doefab.reconstruction.specs import make_batch, psf_pair

    def refuse(*a, **k):
        raise AssertionError("measured data drawn")

    for name in ("hdr_real_sample", "depth_real_sample", "real_light", "_hdr_maps", "_motorcycle"):
        monkeypatch.setattr(realdata, name, refuse)
    for task in ("hdr", "hyperspectral", "depth"):
        pair, _ = psf_pair(task, None)
        for split in ("train", "val"):
            make_batch(task, split, [0], 16, pair)
        with pytest.raises(AssertionError, match="measured data drawn"):
            make_batch(task, "real", [0], 16, pair)


def test_a_real_depth_batch_scores_only_measured_pixels():
    """The target is NaN exactly where the disparity was not measured, and the metrics equal those computed by
    hand on the measured pixels alone."""
    from doefab.reconstruction.metrics import depth_metrics
    from doefab.reconstruction.specs import make_batch, psf_pair

    pair, _ = psf_pair("depth", None)
    _, _, target = make_batch("depth", "real", [4], 64, pair)
    t = target[0].numpy()
    assert np.isnan(t).any() and np.isfinite(t).any()
    pred = np.full_like(t, 3.0)
    m = depth_metrics(pred, t)
    k = t[np.isfinite(t)]
    assert np.isclose(m["mae"], np.abs(3.0 - k).mean()) and np.isclose(m["rmse"], np.sqrt(((3.0 - k) ** 2).mean()))
    assert np.isclose(m["delta125"], (np.maximum(3.0 / k, k / 3.0) < 1.25).mean())


def test_adding_the_measured_split_leaves_the_synthetic_split_digest(monkeypatch):
    """The weights' split digest names the generated splits only: the measured split's seeds do not enter it,
    a generated split's seed does."""
    from doefab.reconstruction import data

    before = data.split_components("depth")["splits"]
    monkeypatch.setitem(data.SPLIT_SEEDS, "real", 123)
    monkeypatch.setitem(data.PART_SEEDS, "real", 321)
    assert data.split_components("depth")["splits"] == before
    monkeypatch.setitem(data.SPLIT_SEEDS, "val", 123)
    assert data.split_components("depth")["splits"] != before


def test_the_measured_file_is_what_its_script_wrote():
    """The HDR file names each source file with its SHA-256 and holds float16 RGB maps of the script's size."""
    import json

    with np.load(realdata.HDR_FILE) as z:
        sources = json.loads(str(z["sources"]))
        assert len(sources) == 6 and all(len(s["sha256"]) == 64 for s in sources.values())
        for name in sources:
            a = z[name]
            assert a.dtype == np.float16 and a.ndim == 3 and a.shape[2] == 3 and min(a.shape[:2]) == 400
