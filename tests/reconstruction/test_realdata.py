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


def _find(picture: np.ndarray, patch: np.ndarray) -> tuple[int, int]:
    """Where ``patch`` [S, S] sits in ``picture`` [H, W] (normalised cross-correlation: blind to a gain)."""
    from skimage.feature import match_template

    r = match_template(picture, patch)
    return tuple(int(v) for v in np.unravel_index(np.argmax(r), r.shape))


def _scenes_read_here() -> dict:
    """name → (linear image, disparity in px with NaN where unmeasured, (f px, B m, doffs px)) of every measured
    depth scene, read without ``realdata``: the Motorcycle from scikit-image with its docstring's calibration, the
    others from the PNGs and calibrations ``DEPTH_FILE`` stores."""
    import json

    import imageio.v3 as iio
    from skimage.data import stereo_motorcycle

    left, _, disp = stereo_motorcycle()
    out = {"Motorcycle": ((left / 255.0) ** 2.2, disp.astype(np.float64), (994.978, 0.193001, 31.086))}
    with np.load(realdata.DEPTH_FILE) as z:
        assert int(z["disparity_scale"]) == 256
        for name, src in json.loads(str(z["sources"])).items():
            steps = iio.imread(z[f"{name}_disparity_png"].tobytes()).astype(np.float64)
            c = src["calibration"]
            out[name] = ((iio.imread(z[f"{name}_image_png"].tobytes()) / 255.0) ** 2.2,
                         np.where(steps > 0, steps / 256.0, np.nan), (c["focal_px"], c["baseline_m"], c["doffs_px"]))
    return out


def test_a_depth_sample_is_one_crop_of_image_depth_and_mask_clipped_to_the_planes():
    """Over draws that reach the Motorcycle and the file's scenes: image, depth and mask are cut at the same place
    of one scene (found by matching the crop in every scene's image), the image scaled by one gain in the synthetic
    scenes' range and the depth that scene's calibration gives, clipped to the planes; ``drawn_depth_scene`` names
    that scene."""
    scenes = _scenes_read_here()
    seen = set()
    for seed in (*range(15), 21, 23):  # draws that reach every scene
        scene, depth, known = realdata.depth_real_sample(np.random.default_rng(seed), 120, 2.2, 3.0)
        assert scene.shape == (3, 120, 120) and depth.shape == known.shape == (120, 120)
        found = {n: _find(v[0][..., 1], scene[1]) for n, v in scenes.items()}
        for name, (y, x) in found.items():
            crop = scenes[name][0][y:y + 120, x:x + 120].transpose(2, 0, 1)
            gain = scene.sum() / crop.sum()
            if np.allclose(scene, crop * gain, rtol=1e-4, atol=1e-6):
                break
        else:
            raise AssertionError(f"draw {seed}: the crop is in no measured scene's image")
        seen.add(name)
        # the scene the sample's generator draws is the one the crop was cut from (what names a scene's source)
        assert realdata.depth_scenes()[realdata.drawn_depth_scene(np.random.default_rng(seed))][0] == name
        _, disp, (f, b, doffs) = scenes[name]
        d = disp[y:y + 120, x:x + 120]
        assert 0.8 <= gain <= 1.8 and np.array_equal(known, np.isfinite(d))
        assert np.allclose(depth[known], np.clip(f * b / (d[known] + doffs), 2.2, 3.0), rtol=1e-6)
        assert 2.2 <= depth.min() and depth.max() <= 3.0
    assert seen == set(scenes), seen  # both sources, every scene


def test_a_scene_larger_than_the_measured_maps_is_one_error_naming_the_size_that_fits():
    from doefab.errors import DoefabError

    with pytest.raises(DoefabError, match=r"--size 369 or less"):
        realdata.check_side("depth", 370, 47)  # the lowest scene, Playtable, is 463 px high: 369 + 2 × 47 = 463
    with pytest.raises(DoefabError, match="smallest measured hdr map"):
        realdata.hdr_real_sample(np.random.default_rng(0), 401)
    realdata.check_side("depth", 369, 47)
    realdata.check_side("hyperspectral", 4096, 95)  # its layout takes any size


def test_generated_scene_functions_refuse_the_measured_split():
    from doefab.errors import DoefabError
    from doefab.reconstruction.data import depth_sample, hdr_sample

    for f in (lambda: hdr_sample(np.random.default_rng(0), 16, "real"),
              lambda: depth_sample(np.random.default_rng(0), 16, "real")):
        with pytest.raises(DoefabError, match="realdata"):
            f()


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
        # below the cap, one map's crop (channels in order) times one gain
        found = False
        for m in maps:
            if min(m.shape[:2]) < 150:
                continue
            y, x = _find(m[..., 1], s[1])
            crop = m[y:y + 150, x:x + 150].transpose(2, 0, 1)
            below = s < 255.0
            g = np.median(s[below] / np.maximum(crop[below], 1e-12))
            if np.allclose(s[below], crop[below] * g, rtol=1e-4, atol=1e-6):
                found = True
                break
        assert found
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

    for name in ("hdr_real_sample", "depth_real_sample", "real_light", "_hdr_maps", "_motorcycle", "_middlebury",
                 "depth_scenes"):
        monkeypatch.setattr(realdata, name, refuse)
    for task in ("hdr", "hyperspectral", "depth"):
        pair, _ = psf_pair(task, None)
        for split in ("train", "val", "test", "final"):
            make_batch(task, split, [0], 16, pair)
        with pytest.raises(AssertionError, match="measured data drawn"):
            make_batch(task, "real", [0], 16, pair)


def test_a_real_depth_batch_scores_only_measured_pixels():
    """The target is NaN exactly where the disparity was not measured, and the metrics equal those computed by
    hand on the measured pixels alone."""
    from doefab.reconstruction.data import sample_rng
    from doefab.reconstruction.metrics import depth_metrics
    from doefab.reconstruction.specs import crop_margin, make_batch, psf_pair

    pair, _ = psf_pair("depth", None)
    _, _, target = make_batch("depth", "real", [4], 64, pair)
    t = target[0].numpy()
    m_px = crop_margin("depth", pair)
    _, _, known = realdata.depth_real_sample(sample_rng("real", 4), 64 + 2 * m_px, 1.0, 5.0)
    assert np.array_equal(np.isnan(t), ~known[m_px:m_px + 64, m_px:m_px + 64])
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
    monkeypatch.setitem(data.CONTENT, "real", "test")
    assert data.split_components("depth")["splits"] == before
    monkeypatch.setitem(data.SPLIT_SEEDS, "val", 123)
    assert data.split_components("depth")["splits"] != before


def test_the_measured_set_takes_no_training_or_test_content_and_its_digest_sees_a_change(monkeypatch):
    """The measured set's content pool is the validation split's; its digest (recorded by a real evaluation)
    changes with its seed and its content pool."""
    from doefab.reconstruction import data

    assert data.CONTENT["real"] not in ("train", "test")
    before = data.real_components()
    monkeypatch.setitem(data.SPLIT_SEEDS, "real", 1)
    assert data.real_components()["definition"] != before["definition"]
    monkeypatch.undo()
    monkeypatch.setitem(data.CONTENT, "real", "test")
    assert data.real_components()["definition"] != before["definition"]


@pytest.mark.parametrize("file, reader", [("HDR_FILE", "_hdr_maps"), ("DEPTH_FILE", "_middlebury")])
def test_a_changed_measured_file_is_refused(file, reader, tmp_path, monkeypatch):
    from doefab.errors import DoefabError

    bad = tmp_path / getattr(realdata, file).name
    data = bytearray(getattr(realdata, file).read_bytes())
    data[len(data) // 2] ^= 0xFF  # one byte changed
    bad.write_bytes(bytes(data))
    monkeypatch.setattr(realdata, file, bad)
    getattr(realdata, reader).cache_clear()
    try:
        with pytest.raises(DoefabError, match="SHA-256 differs"):
            getattr(realdata, reader)()
    finally:
        getattr(realdata, reader).cache_clear()


def test_the_measured_file_is_what_its_script_wrote():
    """The HDR file names each source file with its SHA-256 and holds float16 RGB maps of the script's size."""
    import json

    with np.load(realdata.HDR_FILE) as z:
        sources = json.loads(str(z["sources"]))
        assert len(sources) == 6 and all(len(s["sha256"]) == 64 for s in sources.values())
        for name in sources:
            a = z[name]
            assert a.dtype == np.float16 and a.ndim == 3 and a.shape[2] == 3 and min(a.shape[:2]) == 400
