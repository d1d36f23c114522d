import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError


def test_mixing_is_eq29():
    rng = np.random.default_rng(0)
    left, right = rng.random((3, 8, 8)), rng.random((3, 8, 8))
    a, b = 0.12, 0.07
    ls, rs = doefab.mix_crosstalk(left, right, a, b)
    np.testing.assert_allclose(ls, (1 - a) * left + b * right)
    np.testing.assert_allclose(rs, (1 - b) * right + a * left)
    # light is redistributed, not created
    np.testing.assert_allclose(ls + rs, left + right)


@pytest.mark.parametrize("per_column", [False, True])
def test_round_trip_is_exact(per_column):
    rng = np.random.default_rng(1)
    left, right = rng.random((3, 16, 16)), rng.random((3, 16, 16))
    a = rng.uniform(0.02, 0.2, (1, 16)) if per_column else 0.15
    b = rng.uniform(0.02, 0.2, (1, 16)) if per_column else 0.1
    l2, r2 = doefab.unmix_crosstalk(*doefab.mix_crosstalk(left, right, a, b), a, b)
    np.testing.assert_allclose(l2, left, atol=1e-12)
    np.testing.assert_allclose(r2, right, atol=1e-12)
    # torch, float32: float precision
    lt, rt = torch.from_numpy(left).float(), torch.from_numpy(right).float()
    l3, r3 = doefab.unmix_crosstalk(*doefab.mix_crosstalk(lt, rt, a, b), a, b)
    assert float((l3 - lt).abs().max()) < 1e-6 and float((r3 - rt).abs().max()) < 1e-6


def test_seed_eq32_is_not_the_inverse():
    """The erratum: the printed Eq. 32 does not undo Eq. 29 (our inverse does, above)."""
    left, right, a, b = 0.6, 0.3, 0.15, 0.1
    ls, rs = doefab.mix_crosstalk(left, right, a, b)
    r_eq32 = (rs - a * ls) / (1 - b**2 - a * b + a**2)
    assert abs(r_eq32 - right) > 1e-3


def test_calibration_recovers_known_per_column_ratios():
    rng = np.random.default_rng(2)
    a = rng.uniform(0.02, 0.25, (1, 32))
    b = rng.uniform(0.02, 0.25, (1, 32))
    wall = 0.8 + 0.05 * rng.random((24, 32))  # a white wall, slightly uneven
    blocked_left = doefab.mix_crosstalk(wall, np.zeros_like(wall), a, b)  # DOE half blocked: I_R = 0
    blocked_right = doefab.mix_crosstalk(np.zeros_like(wall), wall, a, b)  # plain half blocked: I_L = 0
    a_hat, b_hat = doefab.calibrate_crosstalk(blocked_left, blocked_right)
    np.testing.assert_allclose(a_hat, a, rtol=1e-10)
    np.testing.assert_allclose(b_hat, b, rtol=1e-10)


def test_near_singular_determinant_is_refused():
    x = np.ones((2, 2))
    with pytest.raises(DoefabError, match="near-singular"):
        doefab.unmix_crosstalk(x, x, 0.5, 0.48)
    with pytest.raises(DoefabError, match="fractions"):
        doefab.mix_crosstalk(x, x, 1.2, 0.0)
    with pytest.raises(DoefabError, match="lit everywhere"):
        doefab.calibrate_crosstalk((x * 0, x * 0), (x, x))


def test_a_ratio_pair_is_physical_only_when_its_determinant_is_positive():
    """Eq. 29's left photodiode records (1 − a) of the left view's light and b of the right's: when
    b ≥ 1 − a (a + b ≥ 1) it collects as large a share of the other half's light as of its own, and so does the
    right one; the views no longer separate. Refused exactly there, whatever the call, naming the argument."""
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    x = np.ones((2, 2))
    for a in np.arange(0.0, 1.0, 0.1):
        for b in np.arange(0.0, 1.0, 0.1):
            physical = a + b < 1 - 1e-12
            for call in (lambda: doefab.mix_crosstalk(x, x, a, b), lambda: DualPixelCrosstalk(a, b)):
                if physical:
                    call()
                else:
                    with pytest.raises(DoefabError, match=r"alpha_lr, alpha_rl = .* is no dual-pixel crosstalk"):
                        call()
    with pytest.raises(DoefabError, match=r"\(0\.7, 0\.4\) at column 2 .* 1 − α_l→r − α_r→l = -0\.1 ≤ 0"):
        doefab.mix_crosstalk(np.ones((2, 3)), np.ones((2, 3)), np.array([0.1, 0.5, 0.7]), 0.4)
    with pytest.raises(DoefabError, match="no dual-pixel crosstalk"):
        doefab.simulate_calibration(0.6, 0.6, rows=8)


def test_views_of_two_shapes_are_refused_by_name():
    """Two views of one capture have one shape; numpy would broadcast a [1, W] view against an [H, W] one, torch
    raise its own shape error: both are refused by name, in both directions of Eq. 29."""
    for a, b in ((np.ones((4, 6)), np.ones((1, 6))), (torch.ones(1, 3, 8, 8), torch.ones(1, 3, 4, 4))):
        with pytest.raises(DoefabError, match="left and right must be the two views of one capture"):
            doefab.mix_crosstalk(a, b, 0.1, 0.05)
        with pytest.raises(DoefabError, match="left_star and right_star must be the two views"):
            doefab.unmix_crosstalk(a, b, 0.1, 0.05)


def test_a_dim_calibration_is_noisy_but_not_biased():
    """A white wall exposed to 1e-3 of full scale: the dark view holds 0.05 · 1e-3 · 25 000 = 1.25 e⁻ against 3 e⁻ of
    read noise, which scatters about 0; clipping it at 0 (or any floor) turned that noise into light (the estimate
    read 0.079 for 0.05). Averaged over 3072 rows, the estimate's spread is about 3 e⁻ / √3072 / 25 e⁻ = 0.002."""
    a, b = doefab.simulate_calibration(0.05, 0.05, rows=3072, level=1e-3, rng=0)
    assert abs(float(a.mean()) - 0.05) < 0.006 and abs(float(b.mean()) - 0.05) < 0.006, (a, b)


def test_captures_that_give_a_ratio_outside_zero_to_one_are_named_at_the_calibration():
    """A view below black (−0.01 after a wrong black level) gives α = 0.5 / 0.49 = 1.02: refused where it arises,
    naming the captures, not later as "no dual-pixel crosstalk". Dark-subtracted pixels that scatter below 0 while
    their column's mean is positive are data, not an error."""
    lit, below = np.full((4, 3), 0.5), np.full((4, 3), -0.01)
    with pytest.raises(DoefabError, match=r"α_l→r = 1.02 \(column 0\), outside \[0, 1\).*black level"):
        doefab.calibrate_crosstalk((below, lit), (lit, np.full((4, 3), 0.02)))
    scatter = np.array([[0.03], [-0.01], [0.02], [0.0]]) * np.ones((1, 3))  # mean 0.01 of a 0.5 wall
    a_lr, _ = doefab.calibrate_crosstalk((np.full((4, 3), 0.49), scatter), (np.full((4, 3), 0.02), lit))
    assert np.allclose(a_lr, 0.01 / 0.5)
    # a ratio below 0 within its rows' noise (−0.005 against a standard error of 0.0135): a ratio of 0
    noisy = np.array([[0.01], [-0.02], [0.005], [-0.005]]) * np.ones((1, 3))
    a_lr, _ = doefab.calibrate_crosstalk((np.full((4, 3), 0.5), noisy), (np.full((4, 3), 0.02), lit))
    assert np.all(a_lr == 0.0)
    with pytest.raises(DoefabError, match=r"α_l→r = -0.0204 \(column 0\)"):  # the same mean, but every row: black
        doefab.calibrate_crosstalk((lit, np.full((4, 3), -0.01)), (np.full((4, 3), 0.02), lit))
    with pytest.raises(DoefabError, match=r"\(row 0, column 0\)"):  # per pixel: the pixel named
        doefab.calibrate_crosstalk((below, lit), (lit, np.full((4, 3), 0.02)), axis_mean=None)


@pytest.mark.parametrize("seed", range(5))
def test_a_simulated_calibration_of_no_crosstalk_reads_zero_not_an_error(seed):
    """True ratios of 0: the estimate scatters about 0 with the dark view's noise; a simulation cuts it to [0, 1)
    instead of refusing its own captures (three of five seeds read below 0)."""
    a, b = doefab.simulate_calibration(0.0, 0.0, rng=seed)
    assert 0 <= float(a.min()) and float(a.max()) < 1e-4 and 0 <= float(b.min()) and float(b.max()) < 1e-4
    assert doefab.DualPixelCrosstalk.calibrated(0.0, 0.0, seed=seed).estimate[0] >= 0


@pytest.mark.parametrize("alpha, rows, level, read_noise", [(0.05, 16, 0.05, 3.0), (0.2, 4, 0.02, 3.0),
                                                            (0.05, 16, 0.05, 40.0), (0.3, 16, 0.01, 40.0)])
def test_calibration_scatter_is_the_simulated_calibrations(alpha, rows, level, read_noise):
    """The delta-method scatter of one column's ratio against the spread of 6000 simulated calibrations of the same
    true ratio (Poisson shot noise and Gaussian read noise drawn per pixel): shot-noise bound and read-noise bound,
    the last at a large ratio, where the read noise's weight 1 − 2α + 2α² (both views carry it, the ratio's
    covariance) differs most from 1."""
    from doefab.imaging.crosstalk import calibration_scatter
    from doefab.imaging.sensor import PoissonGaussian

    cols = 6000
    a_hat, _ = doefab.simulate_calibration(np.full(cols, alpha), np.full(cols, 0.05), rows=rows, rng=1, level=level,
                                           noise=PoissonGaussian(25_000.0, read_noise))
    simulated = float(np.std(a_hat, ddof=1)) / alpha  # the SD estimate's own scatter: about 1 %
    assert calibration_scatter(alpha, rows, level, 25_000.0, read_noise) == pytest.approx(simulated, rel=0.04)
    assert float(np.mean(a_hat)) == pytest.approx(alpha, rel=0.01)
