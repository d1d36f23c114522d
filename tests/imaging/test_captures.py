import math
import re

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError
from doefab.imaging.captures import convolve, convolve_valid, fft_length, irfft2_crop


def _pair(psf_coded, psf_uncoded, wavelengths, depths):
    return doefab.PSFPair(coded=torch.as_tensor(psf_coded, dtype=torch.float32),
                          uncoded=torch.as_tensor(psf_uncoded, dtype=torch.float32),
                          wavelengths=tuple(wavelengths), depths=tuple(depths), sensor_pitch=5.4e-6)


def _blob_psf(k, sigma, weight=0.5, shift=0):
    y, x = np.mgrid[:k, :k] - k // 2
    g = np.exp(-((x - shift) ** 2 + y**2) / (2 * sigma**2))
    return weight * g / g.sum()


def test_convolution_matches_direct_sum():
    rng = np.random.default_rng(0)
    img = rng.random((1, 12, 10))
    psf = rng.random((1, 5, 5))
    got = convolve(torch.from_numpy(img), torch.from_numpy(psf)).numpy()[0]
    ref = np.zeros((12, 10))
    for i in range(12):
        for j in range(10):
            for u in range(5):
                for v in range(5):
                    ii, jj = i - (u - 2), j - (v - 2)
                    if 0 <= ii < 12 and 0 <= jj < 10:
                        ref[i, j] += psf[0, u, v] * img[0, ii, jj]
    np.testing.assert_allclose(got, ref, atol=1e-10)


def test_fft_length_is_the_smallest_even_5_smooth_length_not_below_n():
    def smooth5(m):
        for p in (2, 3, 5):
            while m % p == 0:
                m //= p
        return m == 1

    for n in [1, 2, 7, 73, 75, 300, 606, 1118]:
        want = next(m for m in range(max(n, 2), 4 * n + 4) if m % 2 == 0 and smooth5(m))
        assert fft_length(n) == want, n
    assert fft_length(606) == 640  # next_fast_len gives 625, an odd length


def test_convolution_on_a_grown_canvas_matches_scipy():
    from scipy.signal import convolve2d

    rng = np.random.default_rng(1)
    img = rng.random((2, 71, 69))  # 71 + 5 − 1 = 75: next_fast_len's 75 is odd, the canvas grows to 80
    psf = rng.random((2, 5, 5))
    got = convolve(torch.from_numpy(img), torch.from_numpy(psf)).numpy()
    for c in range(2):
        np.testing.assert_allclose(got[c], convolve2d(img[c], psf[c], mode="same"), atol=1e-10)


def test_the_cropped_inverse_transform_is_numpys_inverse_cropped():
    """``irfft2_crop`` (rows cropped between the two passes) against numpy's two-dimensional real inverse FFT,
    cropped afterwards: even and odd canvases, frames off centre and of other heights than widths."""
    rng = np.random.default_rng(5)
    for (h, w), grown, rows, cols in [((40, 36), (0, 0), slice(3, 30), slice(5, 36)),
                                      ((33, 45), (0, 0), slice(0, 33), slice(7, 19)),
                                      ((16, 17), (0, 0), slice(9, 12), slice(0, 4)),
                                      ((24, 20), (5, 6), slice(2, 22, 3), slice(1, 20))]:
        spec = np.fft.rfft2(rng.standard_normal((2, 3, h, w)), s=(h + grown[0], w + grown[1]))
        # imaginary parts no real image has (columns 0 and, for an even canvas, the last): kept or dropped as
        # irfft2 keeps or drops them
        spec[..., 1:, 0] += 0.3j
        spec[..., 2:, -1] -= 0.2j
        got = irfft2_crop(torch.from_numpy(spec), (h, w), rows, cols).numpy()
        np.testing.assert_allclose(got, np.fft.irfft2(spec, s=(h, w))[..., rows, cols], atol=1e-12)


def test_valid_convolution_matches_scipy_on_the_frames_own_canvas():
    from scipy.signal import convolve2d

    rng = np.random.default_rng(2)
    # rectangular frames, odd and even kernels, non-square kernels; 41 and 38 are not fast lengths
    for (h, w), (kh, kw) in [((41, 38), (7, 7)), ((40, 33), (6, 9)), ((12, 12), (12, 12))]:
        img = rng.random((2, h, w))
        psf = rng.random((2, kh, kw))
        got = convolve_valid(torch.from_numpy(img), torch.from_numpy(psf)).numpy()
        assert got.shape == (2, h - kh + 1, w - kw + 1)
        for c in range(2):
            np.testing.assert_allclose(got[c], convolve2d(img[c], psf[c], mode="valid"), atol=1e-10)
    with pytest.raises(DoefabError, match="at least as large as the PSF"):
        convolve_valid(torch.rand(1, 8, 8), torch.rand(1, 9, 9))


def test_energy_is_conserved_before_clipping():
    k = 15
    psf = np.stack([_blob_psf(k, s) for s in (1.0, 2.0, 3.0)])[None]
    pair = _pair(psf, psf * 0.9, (656e-9, 589e-9, 486e-9), (5.0,))
    scene = np.zeros((3, 64, 64), np.float32)
    scene[:, 24:40, 24:40] = 0.5  # compact: all blurred light stays in the frame, nothing reaches 1
    coded, uncoded = doefab.simulate_captures(scene, pair, noise="none")
    np.testing.assert_allclose(coded.sum(axis=(1, 2)), scene.sum(axis=(1, 2)) * psf[0].sum(axis=(1, 2)), rtol=1e-4)
    np.testing.assert_allclose(uncoded.sum(), 0.9 * coded.sum(), rtol=1e-4)
    assert coded.dtype == np.float32 and coded.shape == (3, 64, 64)
    # a half-exposure: a uniform scene of 1 gives ~0.5 away from the borders
    flat, _ = doefab.simulate_captures(np.ones((3, 64, 64), np.float32), pair, noise="none")
    assert flat[:, 32, 32] == pytest.approx([0.5] * 3, abs=1e-4)


def test_occluding_layer_hides_what_is_behind():
    k = 9
    psf_far, psf_near = _blob_psf(k, 1.0, 1.0), _blob_psf(k, 1.5, 1.0)
    psf = np.stack([psf_near[None], psf_far[None]])  # planes: 1 m, 5 m
    pair = _pair(psf, psf, (550e-9,), (1.0, 5.0))
    h = w = 48
    depth = np.full((h, w), 5.0, np.float32)
    depth[:, : w // 2] = 1.0  # a near wall over the left half
    scene = np.full((1, h, w), 0.2, np.float32)
    scene[0, :, : w // 2] = 0.0  # the near wall is black
    far_only = np.full((1, h, w), 0.2, np.float32)
    # plain sum (Eq. 27 literally) would let the far plane's light spill into the black near wall; occlusion not
    coded, _ = doefab.simulate_captures(np.repeat(scene, 1, 0), pair, depth_map=depth, response=np.ones((3, 1)),
                                        noise="none")
    assert coded[0, h // 2, 5] == pytest.approx(0.0, abs=1e-6)  # deep inside the black near wall
    far_mask = torch.from_numpy((depth == 5.0).astype(np.float32))
    plain = convolve(torch.from_numpy(far_only) * far_mask, torch.from_numpy(psf_far[None])).numpy()[0]
    # at the wall's edge the plain sum lets far light spill onto the near wall; occlusion lets far less through
    assert coded[0, h // 2, w // 2 - 1] < 0.5 * plain[h // 2, w // 2 - 1]
    assert coded[0, h // 2, w - 5] == pytest.approx(0.2, abs=1e-4)


def test_spectral_scene_uses_the_sensor_response():
    lams = np.arange(400, 701, 50) * 1e-9
    t = doefab.sensor_response(lams)
    assert t.shape == (3, len(lams)) and t.min() >= 0 and t.sum(axis=1).max() == pytest.approx(1, abs=1e-6)
    k = 7
    psf = np.zeros((1, len(lams), k, k))
    psf[0, :, k // 2, k // 2] = 0.5  # a delta: the capture is 0.5 · T @ spectrum
    pair = _pair(psf, psf, lams, (math.inf,))
    spectrum = np.linspace(0.2, 0.8, len(lams)).astype(np.float32)
    scene = np.broadcast_to(spectrum[:, None, None], (len(lams), 16, 16)).copy()
    coded, _ = doefab.simulate_captures(scene, pair, response=t, noise="none")
    np.testing.assert_allclose(coded[:, 8, 8], 0.5 * t @ spectrum, rtol=1e-5)


def test_a_sensor_gives_the_captures_its_noise():
    """A 500 e⁻, 10 e⁻ sensor: a capture at 0.4 scatters by √(0.4 · 500 + 10²) / 500."""
    psf = np.zeros((1, 3, 3, 3))
    psf[0, :, 1, 1] = 0.5
    pair = _pair(psf, psf, (656e-9, 589e-9, 486e-9), (5.0,))
    scene = np.full((3, 128, 128), 0.8, np.float32)  # capture 0.4
    coded, _ = doefab.simulate_captures(scene, pair, noise=doefab.Sensor(full_well_e=500.0, read_noise_e=10.0))
    assert coded.std() == pytest.approx(math.sqrt(0.4 * 500 + 100) / 500, rel=0.05)


def test_noise_is_seeded_and_has_the_stated_size():
    psf = np.zeros((1, 3, 3, 3))
    psf[0, :, 1, 1] = 0.5
    pair = _pair(psf, psf, (656e-9, 589e-9, 486e-9), (5.0,))
    scene = np.full((3, 128, 128), 0.8, np.float32)  # capture 0.4
    a = doefab.simulate_captures(scene, pair, seed=3)
    b = doefab.simulate_captures(scene, pair, seed=3)
    assert np.array_equal(a[0], b[0]) and not np.array_equal(a[0], doefab.simulate_captures(scene, pair, seed=4)[0])
    # Poisson–Gaussian: variance of (0.4 · 25000 e⁻ shot + 3 e⁻ read) / 25000
    expected = math.sqrt(0.4 * 25000 + 9) / 25000
    assert a[0].std() == pytest.approx(expected, rel=0.05)
    u, _ = doefab.simulate_captures(scene, pair, noise="authors")
    assert np.abs(u - 0.4).max() <= 0.01 + 1e-6 and u.std() == pytest.approx(0.02 / math.sqrt(12), rel=0.05)


@pytest.mark.parametrize("bad, match", [
    (lambda s: s[:2], "2 bands"),
    (lambda s: s[0], "3 dimensions"),
    (lambda s: np.where(s > 0.5, np.nan, s), "NaN"),
    (lambda s: s - 1.0, "negative radiance"),
])
def test_bad_scenes_give_one_clear_error(bad, match):
    psf = np.zeros((1, 3, 3, 3))
    psf[0, :, 1, 1] = 0.5
    pair = _pair(psf, psf, (656e-9, 589e-9, 486e-9), (5.0,))
    scene = np.random.default_rng(0).random((3, 8, 8)).astype(np.float32)
    with pytest.raises(DoefabError, match=match):
        doefab.simulate_captures(bad(scene), pair)


def test_multi_depth_pair_needs_a_depth_map():
    psf = np.zeros((2, 3, 3, 3))
    pair = _pair(psf, psf, (656e-9, 589e-9, 486e-9), (1.0, 5.0))
    with pytest.raises(DoefabError, match="depth_map"):
        doefab.simulate_captures(np.zeros((3, 8, 8), np.float32), pair)


def _crosstalk_case():
    rng = np.random.default_rng(4)
    scene = rng.uniform(0.05, 0.9, (3, 24, 40))
    pair = _pair(np.stack([_blob_psf(9, 1.5, shift=2)] * 3)[None], np.stack([_blob_psf(9, 1.0)] * 3)[None],
                 (656e-9, 589e-9, 486e-9), (5.0,))
    return scene, pair


def test_crosstalk_mixes_both_views_per_column_as_eq_29_says():
    """With per-column ratios and no calibration, the recorded coded (right) view is α_l→r·uncoded +
    (1 − α_r→l)·coded, column by column (noise off)."""
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    scene, pair = _crosstalk_case()
    clean_c, clean_u = doefab.simulate_captures(scene, pair, noise="none")
    a = np.linspace(0.02, 0.12, 40)
    b = np.linspace(0.10, 0.03, 40)
    c, u = doefab.simulate_captures(scene, pair, noise="none", crosstalk=DualPixelCrosstalk(a, b))
    np.testing.assert_allclose(c, a * clean_u + (1 - b) * clean_c, atol=2e-7)
    np.testing.assert_allclose(u, (1 - a) * clean_u + b * clean_c, atol=2e-7)


def test_a_calibrated_pipeline_leaves_the_calibrations_error_and_no_more():
    """Unmixed with the exact ratios the clean views come back; with estimates off by δ the residual is the
    2 × 2 algebra's (numpy's inverse of the estimated mix times the true one), linear in δ."""
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    scene, pair = _crosstalk_case()
    clean_c, clean_u = doefab.simulate_captures(scene, pair, noise="none")
    a, b = 0.08, 0.05
    exact = doefab.simulate_captures(scene, pair, noise="none", crosstalk=DualPixelCrosstalk(a, b, (a, b)))
    np.testing.assert_allclose(exact[0], clean_c, atol=1e-6)
    np.testing.assert_allclose(exact[1], clean_u, atol=1e-6)
    errs = []
    for d in (0.004, 0.002):
        got = doefab.simulate_captures(scene, pair, noise="none", crosstalk=DualPixelCrosstalk(a, b, (a + d, b - d)))
        m = np.linalg.inv([[1 - (a + d), b - d], [a + d, 1 - (b - d)]]) @ np.array([[1 - a, b], [a, 1 - b]])
        np.testing.assert_allclose(got[0], m[1, 0] * clean_u + m[1, 1] * clean_c, atol=2e-6)
        errs.append(np.abs(got[0] - clean_c).max())
    assert errs[0] == pytest.approx(2 * errs[1], rel=0.02)


def test_crosstalk_refuses_ratios_that_are_not_fractions():
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    with pytest.raises(DoefabError, match="crosstalk fractions"):
        DualPixelCrosstalk(5.0, 0.05)  # percent typed where a fraction belongs
    scene, pair = _crosstalk_case()
    with pytest.raises(DoefabError, match="crosstalk must be"):
        doefab.simulate_captures(scene, pair, crosstalk="yes")


def test_an_impossible_crosstalk_pair_is_refused_naming_the_argument():
    """(0.6, 0.6): each a fraction, but 1 − 0.6 − 0.6 < 0 — each photodiode would hold more of the other
    half's light than of its own (``crosstalk.check_pair``)."""
    scene, pair = _crosstalk_case()
    with pytest.raises(DoefabError, match=r"^crosstalk α_l→r, α_r→l = \(0\.6, 0\.6\) is no dual-pixel crosstalk.*"
                                          r"e\.g\. \(0\.05, 0\.05\)"):
        doefab.simulate_captures(scene, pair, crosstalk=(0.6, 0.6))
    doefab.simulate_captures(scene, pair, crosstalk=(0.6, 0.3))  # one large ratio, the views still separate


@pytest.mark.parametrize("scale, dtype", [(1e30, np.float32), (1e300, np.float64), (2.6e6, np.float32)])
def test_a_scene_brighter_than_any_camera_records_is_refused_naming_scene(scale, dtype):
    """Radiance beyond MAX_RADIANCE (1e6 × the clipping level; the scene below peaks at 0.9 × scale): one
    DoefabError naming the scene, its peak and the factor that brings it to 100 — not numpy's Poisson overflow
    or a float32 infinity."""
    from doefab.imaging.captures import MAX_RADIANCE

    scene, pair = _crosstalk_case()
    top = float(scene.max()) * scale
    with pytest.raises(DoefabError, match=rf"^scene holds radiance up to {re.escape(f'{top:.3g}')}: .* up to "
                                          rf"1e\+06 .*multiply it by {re.escape(f'{100 / top:.3g}')}"):
        doefab.simulate_captures((scene * scale).astype(dtype), pair)
    bright = scene * (MAX_RADIANCE / scene.max())  # at the limit: recorded, and clipped where the light is
    coded, _ = doefab.simulate_captures(bright, pair, seed=0)
    assert np.isfinite(coded).all() and coded.max() == 1.0


def test_a_response_that_would_overflow_the_noise_is_refused_naming_response():
    """A spectral scene of radiance 1 through a response of 1e30: the RGB light would be 1e30 — one error naming
    ``response`` and the normalised one, not numpy's Poisson overflow."""
    psf = np.zeros((1, 1, 3, 3))
    psf[0, :, 1, 1] = 0.5
    pair = _pair(psf, psf, (550e-9,), (5.0,))
    scene = np.ones((1, 8, 8), np.float32)
    with pytest.raises(DoefabError, match=r"^response sums to 1e\+30 .* would reach 1e\+30.*doefab\.sensor_response"):
        doefab.simulate_captures(scene, pair, response=np.full((3, 1), 1e30))
    coded, _ = doefab.simulate_captures(scene, pair, response=np.full((3, 1), 1.0), noise="none")
    assert np.allclose(coded, 0.5)


def test_captures_name_the_pair_they_were_recorded_through():
    """A capture is a numpy array (or tensor) with ``pair``: crops and arithmetic keep it, one number is a plain
    scalar."""
    scene, pair = _crosstalk_case()
    coded, uncoded = doefab.simulate_captures(scene, pair, noise="none")
    assert isinstance(coded, np.ndarray) and coded.pair is pair and uncoded.pair is pair
    assert coded[:, 4:12].pair is pair and (2 * coded).pair is pair
    assert type(coded.mean()) is np.float32 and type(np.asarray(coded)) is np.ndarray
    ct, _ = doefab.simulate_captures(torch.from_numpy(scene), pair, noise="none")
    assert type(ct) is torch.Tensor and ct.pair is pair and torch.equal(ct, torch.from_numpy(np.asarray(coded)))


def test_a_calibrated_camera_estimates_its_ratios_from_noisy_white_walls():
    """``DualPixelCrosstalk.calibrated``: the estimate's error shrinks as the calibration uses more rows (shot
    noise averages as 1/√rows), is zero-mean across seeds, and the captures through it stay within that error
    of the clean ones."""
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    a = np.linspace(0.03, 0.07, 40)
    b = np.linspace(0.06, 0.04, 40)
    err = {}
    for rows in (16, 1024):
        cams = [DualPixelCrosstalk.calibrated(a, b, rows=rows, seed=s) for s in range(6)]
        est = np.array([c.estimate[0] for c in cams])
        err[rows] = float(np.sqrt(((est - a) ** 2).mean()))
        assert abs(float((est - a).mean())) < 3 * err[rows] / np.sqrt(est.size) + 1e-4  # unbiased
    assert 4 < err[16] / err[1024] < 16  # √(1024/16) = 8
    scene, pair = _crosstalk_case()
    clean_c, clean_u = doefab.simulate_captures(scene, pair, noise="none")
    mixed, _ = doefab.simulate_captures(scene, pair, noise="none", crosstalk=DualPixelCrosstalk(a, b))
    left_in = np.abs(mixed - clean_c).max()  # what an uncalibrated pipeline leaves in
    assert left_in > 5e-3
    off = {}
    for rows in (16, 1024):
        cam = DualPixelCrosstalk.calibrated(a, b, rows=rows, seed=0)
        got, _ = doefab.simulate_captures(scene, pair, noise="none", crosstalk=cam)
        off[rows] = np.abs(got - clean_c).max()
        # the unmix's first-order error: the ratios' errors times the other view, over the determinant
        d_a, d_b = np.abs(np.asarray(cam.estimate) - np.stack([a, b]))
        bound = ((d_a * clean_u.max() + d_b * clean_c.max()) / (1 - a - b)).max()
        assert 1e-6 < off[rows] < 1.5 * bound
    assert off[1024] < 0.25 * left_in and off[1024] < off[16] / 3  # the calibration removes the mix; more rows, less
    with pytest.raises(DoefabError, match="rows"):
        DualPixelCrosstalk.calibrated(0.05, 0.05, rows=0)


@pytest.mark.parametrize("a, b", [(0.05, 0.05), (0.037, 0.063), (0.063, 0.037)])
def test_a_pixel_saturated_in_the_raw_capture_stays_saturated_after_the_unmix(a, b):
    """Where both photodiodes saturate, the unmix of two clipped values is ((1−b) − b)/(1−a−b) for the left
    view: 0.971 for a = 0.037, b = 0.063 — below full scale, so it would pass as a measurement of a highlight
    thousands of times brighter. The pipeline keeps it saturated (exactly 1), whatever the ratios."""
    from doefab.imaging.crosstalk import DualPixelCrosstalk
    from doefab.imaging.sensor import noise_model

    coded = np.full((3, 4, 6), 0.3)
    uncoded = np.full((3, 4, 6), 0.3)
    coded[:, 1, 2], uncoded[:, 1, 2] = 40.0, 60.0  # a highlight both views clip
    uncoded[:, 2, 4] = 5.0  # one only the plain view clips
    cam = DualPixelCrosstalk(a, b, (a, b))
    c, u = cam.record(coded, uncoded, noise_model("none"), np.random.default_rng(0))
    assert np.all(c[:, 1, 2] == 1.0) and np.all(u[:, 1, 2] == 1.0)
    assert np.all(u[:, 2, 4] == 1.0)
    np.testing.assert_allclose(c[:, 0, 0], 0.3, atol=1e-12)  # unclipped pixels unmix exactly
    naive_l, naive_r = doefab.unmix_crosstalk(np.ones(3), np.ones(3), a, b)  # the unmix alone, both clipped
    assert (min(naive_l.min(), naive_r.min()) < 0.98) == (a != b)  # the case the check guards against does arise


def test_depths_beyond_the_pairs_planes_are_refused():
    """A depth map at 30 m, or at 0.5 mm (millimetres typed as metres), through planes at 1 and 5 m would be
    rendered at the nearest plane: refused, naming the span; depths on the planes and between them pass."""
    k = 9
    psf = np.stack([_blob_psf(k, 1.5, 1.0)[None], _blob_psf(k, 1.0, 1.0)[None]])  # planes: 1 m, 5 m
    pair = _pair(psf, psf, (550e-9,), (1.0, 5.0))
    scene = np.full((1, 16, 16), 0.2, np.float32)
    for bad in (30.0, 0.0005):
        with pytest.raises(doefab.DoefabError, match=r"spans .* beyond the PSF pair's planes \(1–5 m\)"):
            doefab.simulate_captures(scene, pair, depth_map=np.full((16, 16), bad, np.float32),
                                     response=np.ones((3, 1)), noise="none")
    ok = np.linspace(1.0, 5.0, 256, dtype=np.float32).reshape(16, 16)
    coded, _ = doefab.simulate_captures(scene, pair, depth_map=ok, response=np.ones((3, 1)), noise="none")
    assert np.isfinite(coded).all()
