"""A real sensor's crosstalk (``SensorCrosstalk``): dependent on the light's angle along both axes and on the half
it came through, varying from row to row, drifting between calibration and capture — and the residual a per-column
white-wall calibration (Eq. 30–31) leaves of it."""

from statistics import NormalDist

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.imaging.crosstalk import check_pair, mix_crosstalk, simulate_calibration
from doefab.imaging.sensorcrosstalk import SensorCrosstalk
from doefab.imaging.sensor import noise_model

PHI = NormalDist()


def test_the_ratios_follow_the_spot_model_along_both_axes_and_per_half():
    """Without row variation and drift the ratios are Φ((z + k·u) / (1 + g·(u² + v²))), computed here with the
    standard library's normal distribution: the budget's slope is met at the calibrated edge of the centre row,
    both ratios rise toward the top and bottom edges (along the split line), and the two halves' laws differ."""
    a0, b0, slope, g, w = 0.05, 0.04, 0.02, 0.05, 3072
    s = SensorCrosstalk((a0, b0), slope, spot_growth=g, row_sigma=0.0, drift_sigma=0.0, width_px=w)
    rows, cols = np.array([-1536.0, -700.0, 0.0, 900.0]), np.array([-1536.0, -300.0, 0.0, 500.0, 1536.0])
    a, b = s.ratios(rows, cols, session=0)
    za, zb = PHI.inv_cdf(a0), PHI.inv_cdf(b0)
    ka, kb = PHI.inv_cdf(a0 + slope) * (1 + g) - za, zb - PHI.inv_cdf(b0 - slope) * (1 + g)
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            u, v = c / (w / 2), r / (w / 2)
            widen = 1 + g * (u * u + v * v)
            assert a[i, j] == pytest.approx(PHI.cdf((za + ka * u) / widen), rel=1e-9)
            assert b[i, j] == pytest.approx(PHI.cdf((zb - kb * u) / widen), rel=1e-9)
    centre_row = list(rows).index(0.0)
    assert a[centre_row, -1] == pytest.approx(a0 + slope) and b[centre_row, -1] == pytest.approx(b0 - slope)
    assert a[0, 2] > a[centre_row, 2] and b[0, 2] > b[centre_row, 2]  # the row's place counts, not only the column's
    rise, fall = a[centre_row, 3] - a0, b0 - b[centre_row, 3]
    assert rise > 0 and fall > 0 and abs(rise - fall) > 1e-4  # each half its own law


def test_rows_vary_and_sessions_drift_by_the_stated_sizes():
    """Each row's ratios are the row-free ones × (1 ± ρ) (l→r up when r→l goes down: the row's microlenses sit
    off their photodiodes), ρ of rms ``row_sigma``; a capture session scales each ratio by 1 + δ, δ of rms
    ``drift_sigma``, the same over the whole sensor."""
    s = SensorCrosstalk((0.05, 0.05), 0.0, spot_growth=0.0, row_sigma=0.02, drift_sigma=0.03, seed=5)
    rows, cols = np.arange(3072) - 1536.0, np.array([-400.0, 0.0, 700.0])
    a, b = s.ratios(rows, cols, session=None)
    rho = a / 0.05 - 1
    np.testing.assert_allclose(b / 0.05 - 1, -rho, atol=1e-12)
    np.testing.assert_allclose(rho, rho[:, :1].repeat(3, axis=1), atol=1e-12)  # one value per row
    assert np.std(rho[:, 0]) == pytest.approx(0.02, rel=0.1)
    drifts = []
    for session in range(200):
        a_s, b_s = s.ratios(rows[:4], cols, session)
        d = np.stack([a_s / a[:4], b_s / b[:4]]) - 1
        np.testing.assert_allclose(d, d[:, :1, :1] * np.ones_like(d), atol=1e-12)  # one factor per session and half
        np.testing.assert_allclose(d[:, 0, 0], s.drift(session), atol=1e-12)
        drifts.append(d[:, 0, 0])
    assert np.std(drifts) == pytest.approx(0.03, rel=0.15)
    assert len({tuple(np.round(x, 12)) for x in drifts}) == 200  # every session its own


def test_the_calibration_leaves_a_residual_an_independent_computation_reproduces():
    """A noise-free white-wall calibration (Eq. 30–31) of a uniform wall estimates each column's mean ratio over
    its rows; the residual RMS over the region and the sessions is recomputed here from that mean. It is well above
    zero for a real sensor and nil for one whose crosstalk is per column, as the calibration assumes."""
    s = SensorCrosstalk((0.05, 0.05), 0.02, seed=2)
    grid, sessions, rows = 16, 4, 512
    at = ((np.arange(grid) + 0.5) / grid - 0.5) * 3072
    cal_rows = ((np.arange(rows) + 0.5) / rows - 0.5) * 3072
    a_cal, b_cal = s.ratios(cal_rows, at, session=None)
    mean = np.stack([a_cal.mean(axis=0), b_cal.mean(axis=0)])  # Eq. 31 with I_L = const, I_R = 0: the row mean
    gaps = np.array([np.stack(s.ratios(at, at, k)) - mean[:, None, :] for k in range(sessions)])
    want = np.sqrt((gaps ** 2).mean(axis=(0, 2, 3)))
    got = s.residual(rows, sessions=sessions, grid=grid)
    np.testing.assert_allclose(got, want, rtol=1e-9)
    assert min(got) > 1e-3  # a few per cent of a 5 % ratio
    ideal = SensorCrosstalk((0.05, 0.05), 0.02, spot_growth=0.0, row_sigma=0.0, drift_sigma=0.0)
    assert max(ideal.residual(rows, sessions=sessions, grid=grid)) < 1e-12
    # the calibration's noise (the default sensor, all 3072 rows) adds little to what the model leaves
    assert max(s.residual(noise="default", sessions=sessions, grid=grid)) < 1.1 * max(
        s.residual(sessions=sessions, grid=grid))


def test_a_camera_mixes_with_the_true_map_and_unmixes_with_the_per_column_estimate():
    s = SensorCrosstalk((0.05, 0.05), 0.02, seed=1)
    rows, cols = np.arange(8) + 300.5, np.arange(6) - 900.5
    cam = s.camera(rows, cols, noise="none", session=3, calibration_rows=64, rng=0)
    a, b = s.ratios(rows, cols, 3)
    np.testing.assert_array_equal(cam.alpha_lr, a)
    np.testing.assert_array_equal(cam.alpha_rl, b)
    np.testing.assert_allclose(cam.estimate[0], s.calibrate(cols, 64, "none")[0], rtol=1e-12)
    assert cam.estimate[0].shape == (6,)
    rng = np.random.default_rng(0)
    left, right = 0.2 + 0.3 * rng.random((3, 8, 6)), 0.2 + 0.3 * rng.random((3, 8, 6))  # nothing clips
    coded, plain = cam.record(right, left, noise_model("none"), rng)
    ls, rs = mix_crosstalk(left, right, a, b)
    a_hat, b_hat = cam.estimate
    det = 1 - a_hat - b_hat
    np.testing.assert_allclose(coded, ((1 - a_hat) * rs - a_hat * ls) / det, atol=1e-12)
    assert float(np.abs(coded - right).max()) > 1e-4  # the residual reaches the delivered view


def test_maps_are_checked_and_refused_by_name():
    a = np.full((3, 4), 0.05)
    b = a.copy()
    b[2, 1] = 0.97
    with pytest.raises(DoefabError, match=r"at row 2, column 1 .* 1 − α_l→r − α_r→l = -0\.02 ≤ 0"):
        check_pair(a, b)
    with pytest.raises(DoefabError, match=r"shape \(3, 4\) .* rows = 8"):
        simulate_calibration(a, a, rows=8)
    bad = {"slope": -0.1, "spot_growth": 2.0, "row_sigma": float("nan"), "drift_sigma": True}
    for name, value in bad.items():
        with pytest.raises(DoefabError, match=rf"{name} must be a fraction in \[0, .*got {value!r}; e\.g\. "):
            SensorCrosstalk(**{name: value})
    with pytest.raises(DoefabError, match=r"width_px .* got 3\.5; e\.g\. 3072"):
        SensorCrosstalk(width_px=3.5)
    with pytest.raises(DoefabError, match="no dual-pixel crosstalk"):
        SensorCrosstalk((0.6, 0.5))
    with pytest.raises(DoefabError, match=r"centre must be the pair .* e\.g\. \(0\.05, 0\.05\)"):
        SensorCrosstalk(0.05)
    with pytest.raises(DoefabError, match=r"rows must be a list of finite pixel positions"):
        SensorCrosstalk().ratios([np.nan], [0.0])


@pytest.mark.parametrize("centre", [(0.05, 0.05), (0.3, 0.1)])
def test_the_worst_determinant_is_at_a_corner_of_the_calibrated_region(centre):
    """Without row variation the determinant 1 − α_l→r − α_r→l is least where the spots are widest and the ratios
    highest: a corner of the region (u, v = ±1, rows reach ±(1 − 1/w)). Computed here with the standard library's
    normal distribution from the model's law, Φ((z ± k·u) / (1 + g·(u² + v²))), at the four corners."""
    a0, b0 = centre
    slope, g, w = 0.02, 0.05, 512
    s = SensorCrosstalk((a0, b0), slope, spot_growth=g, row_sigma=0.0, drift_sigma=0.0, width_px=w)
    za, zb = PHI.inv_cdf(a0), PHI.inv_cdf(b0)
    ka, kb = PHI.inv_cdf(a0 + slope) * (1 + g) - za, zb - PHI.inv_cdf(b0 - slope) * (1 + g)
    v = 1 - 1 / w
    corners = [1 - PHI.cdf((za + ka * u) / (1 + g * (1 + v * v))) - PHI.cdf((zb - kb * u) / (1 + g * (1 + v * v)))
               for u in (-1.0, 1.0)]
    det, a, b = s.worst_determinant()
    assert det == pytest.approx(min(corners), abs=1e-9) and det == pytest.approx(1 - a - b, abs=1e-12)
    assert det < 1 - a0 - b0  # below the centre's
    # the fixed row pattern only lowers it further, by about its rms times the ratios' difference at the corner
    rowed = SensorCrosstalk((a0, b0), slope, spot_growth=g, width_px=w).worst_determinant()[0]
    assert det - 0.1 < rowed < det
