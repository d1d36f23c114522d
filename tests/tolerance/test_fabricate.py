"""Fabricated heights against theory and an independent computation (issue: tolerance)."""

import math

import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError
from doefab.tolerance.fabricate import fabricated_height, level_step_for

PITCH = 5.4e-6
LAM = 550e-9


@pytest.fixture(scope="module")
def cam():
    return doefab.Camera(aperture_diameter=0.3e-3, doe_pitch=PITCH, doe_pixels=64, sensor_pitch=5.4e-6,
                         sensor_distance=50e-3, focus_distance=5.0)


def grating_levels(n_levels: int, size: int = 64) -> np.ndarray:
    """A 1-D blazed grating along x: period n_levels pixels, levels 0, 16/N, 2·16/N, ..."""
    row = (np.arange(size) % n_levels) * (16 // n_levels)
    return np.tile(row, (size, 1)).astype(np.uint8)


def first_order_from_samples(h_row: np.ndarray, dx: float, period: float, n: float) -> float:
    """|c₁|² of the piecewise-constant transmission sampled at pitch dx over whole periods (exact integrals)."""
    t = np.exp(2j * np.pi * (n - 1) * h_row / LAM)
    a = np.arange(len(h_row)) * dx
    k = 2 * np.pi / period
    cells = (np.exp(-1j * k * a) - np.exp(-1j * k * (a + dx))) / (1j * k)
    return float(abs(np.sum(t * cells) / (len(h_row) * dx)) ** 2)


def eta_formula(n_levels: int, alpha: float) -> float:
    x = np.pi * (alpha - 1)
    bracket = 1.0 if abs(x) < 1e-12 else math.sin(x) / (n_levels * math.sin(x / n_levels))
    return float(np.sinc(1 / n_levels) ** 2 * bracket**2)


@pytest.mark.parametrize("n_levels", [16, 8, 4])
@pytest.mark.parametrize("alpha", [0.9, 0.97, 1.0, 1.05, 1.1])
def test_depth_scale_follows_the_grating_formula(cam, n_levels, alpha):
    lv = grating_levels(n_levels)
    h = fabricated_height(lv, cam, LAM, depth_scale=(alpha,) * 4, supersample=1)
    n = float(cam.material.index(LAM))
    row = h[32, 16:48]  # whole periods
    assert first_order_from_samples(row, PITCH, n_levels * PITCH, n) == pytest.approx(eta_formula(n_levels, alpha),
                                                                                   abs=1e-10)


@pytest.mark.parametrize("n_levels", [2, 8, 32])
@pytest.mark.parametrize("alpha", [0.9, 1.0, 1.05])
def test_depth_scale_on_an_n_level_process_follows_the_grating_formula(cam, n_levels, alpha):
    """A design made for N levels (log2 N masks, levels 0..N−1, step λ / (n − 1) / N): every mask etched α times too
    deep gives the N-level staircase's first-order efficiency η(N, α)."""
    masks = int(math.log2(n_levels))
    lv = np.tile(np.arange(64) % n_levels, (64, 1)).astype(np.uint8)
    h = fabricated_height(lv, cam, LAM, depth_scale=(alpha,) * masks, supersample=1, n_levels=n_levels)
    assert level_step_for(cam, LAM, n_levels) == pytest.approx(LAM / (float(cam.material.index(LAM)) - 1) / n_levels,
                                                              rel=1e-12)
    n = float(cam.material.index(LAM))
    row = h[32, 16:16 + 32]  # whole periods of N pixels (32 pixels)
    assert first_order_from_samples(row, PITCH, n_levels * PITCH, n) == pytest.approx(eta_formula(n_levels, alpha),
                                                                                    abs=1e-10)
    with pytest.raises(DoefabError, match=f"this design has {masks} mask{'s' if masks != 1 else ''} \\("):
        fabricated_height(lv, cam, LAM, depth_scale=(alpha,) * (masks + 1), n_levels=n_levels)


def test_zero_perturbation_reproduces_the_level_map(cam):
    lv = np.random.default_rng(0).integers(0, 16, (64, 64)).astype(np.uint8)
    for s in (1, 3):
        h = fabricated_height(lv, cam, LAM, supersample=s)
        np.testing.assert_allclose(h, np.kron(doefab.levels_to_height(lv, cam), np.ones((s, s))), rtol=0, atol=1e-18)


def test_whole_pixel_shift_of_every_mask_moves_the_pattern(cam):
    lv = np.random.default_rng(1).integers(0, 16, (64, 64)).astype(np.uint8)
    s = 2
    h0 = fabricated_height(lv, cam, LAM, supersample=s)
    h1 = fabricated_height(lv, cam, LAM, supersample=s, overlay=((PITCH, 0.0),) * 4)  # one pixel toward +x
    np.testing.assert_allclose(h1[:, s:], h0[:, :-s], atol=1e-18)


def _misaligned_staircase_eta(n_levels: int, shifts_px: dict, n: float, d: float) -> float:
    """Independent: exact Fourier series of the 1-D staircase whose masks are shifted by ``shifts_px``."""
    period = n_levels  # pixels
    step = 16 // n_levels
    edges = {0.0, float(period)}
    for m in range(4):
        for k in range(period + 1):
            edges.add((k + shifts_px.get(m, 0.0)) % period)
    xs = np.array(sorted(edges))

    def height(x):  # at position x (pixels) inside one period
        h = 15 * d
        for m in range(4):
            k = int(math.floor((x - shifts_px.get(m, 0.0)) % period))
            level = (k % n_levels) * step
            if ((15 - level) >> m) & 1:
                h -= (1 << m) * d
        return h

    c1 = 0j
    for a, b in zip(xs[:-1], xs[1:]):
        t = np.exp(2j * np.pi * (n - 1) * height(0.5 * (a + b)) / LAM)
        c1 += t * (np.exp(-2j * np.pi * a / period) - np.exp(-2j * np.pi * b / period)) / (2j * np.pi)
    return float(abs(c1) ** 2)


@pytest.mark.parametrize("mask, shift_px", [(0, 0.3), (3, 0.3), (1, 0.5)])
def test_overlay_matches_an_independent_fourier_series(cam, mask, shift_px):
    lv = grating_levels(16)
    n = float(cam.material.index(LAM))
    d = level_step_for(cam, LAM)
    exact = _misaligned_staircase_eta(16, {mask: shift_px}, n, d)
    errs = []
    for s in (2, 8):
        ov = [(0.0, 0.0)] * 4
        ov[mask] = (shift_px * PITCH, 0.0)
        h = fabricated_height(lv, cam, LAM, overlay=ov, supersample=s)
        row = h[32 * s, 16 * s:48 * s]
        errs.append(abs(first_order_from_samples(row, PITCH / s, 16 * PITCH, n) - exact))
    assert errs[1] < 5e-3 and errs[1] <= errs[0] + 1e-12  # agrees, and does not get worse as the grid is refined


def test_coarsest_mask_misalignment_costs_more_than_the_finest(cam):
    """The issue expected the opposite. Physics: a shift δ of mask m leaves slivers of width δ at each of its
    16 / 2^m edges per period with a phase error of 2^m · 2π/16, so the scattered power grows like
    (16 / 2^m) · δ · (2^m)² ∝ 2^m δ: the deepest (coarsest) mask, a π step, matters most for the same shift —
    and even more for the same fraction of its (8× wider) features. Both computations agree on it."""
    lv = grating_levels(16)
    n = float(cam.material.index(LAM))
    d = level_step_for(cam, LAM)
    nominal = _misaligned_staircase_eta(16, {}, n, d)
    loss = {m: nominal - _misaligned_staircase_eta(16, {m: 0.25}, n, d) for m in (0, 3)}
    assert loss[3] > loss[0] > 0
    for m in (0, 3):  # and fabricated_height agrees on the ranking
        ov = [(0.0, 0.0)] * 4
        ov[m] = (0.25 * PITCH, 0.0)
        h = fabricated_height(lv, cam, LAM, overlay=ov, supersample=8)
        loss[m] = nominal - first_order_from_samples(h[256, 128:384], PITCH / 8, 16 * PITCH, n)
    assert loss[3] > loss[0] > 0


def test_edge_bias_roughness_and_bad_units(cam):
    lv = grating_levels(16)
    h0 = fabricated_height(lv, cam, LAM, supersample=4)
    grown = fabricated_height(lv, cam, LAM, supersample=4, edge_bias=0.5e-6)
    assert grown.mean() < h0.mean()  # etched regions grew: less material
    rough = fabricated_height(lv, cam, LAM, supersample=2, roughness=10e-9, seed=3, roughness_corr=2e-6)
    diff = rough - fabricated_height(lv, cam, LAM, supersample=2)
    # a cell holds the surface's mean over its area: variance σ²·G², G = (1/w²)∬ exp(−(x − x')²/ℓ²) dx dx'
    # over the cell (w = 2.7 µm), integrated here numerically
    w, ell = PITCH / 2, 2e-6
    x = (np.arange(400) + 0.5) / 400 * w
    g = np.exp(-((x[:, None] - x[None, :]) / ell) ** 2).mean()
    assert diff.std() == pytest.approx(10e-9 * g, rel=1e-4)
    from doefab.errors import DoefabError

    with pytest.raises(DoefabError, match="unit"):
        fabricated_height(lv, cam, LAM, overlay=((0.5, 0.0),) * 4)  # 0.5 m: someone meant µm


def test_an_error_free_part_is_the_design_on_the_cameras_own_wavelength_by_default():
    """No errors and no design wavelength given: the heights are ``levels_to_height``'s (the camera's design
    wavelength, here 633 nm), not a fixed 550 nm's."""
    from dataclasses import replace

    cam = doefab.Camera(aperture_diameter=0.3e-3, doe_pitch=PITCH, doe_pixels=64, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0, design_wavelength=633e-9)
    lv = grating_levels(8) // 2
    want = doefab.levels_to_height(lv, cam, n_levels=8)
    assert np.abs(fabricated_height(lv, cam, supersample=1, n_levels=8) - want).max() < 1e-15
    n = float(cam.material.index(633e-9))
    assert want.max() == pytest.approx(7 / 8 * 633e-9 / (n - 1), rel=1e-12)  # the level step λ / (n − 1) / L
    other = replace(cam, design_wavelength=550e-9)
    assert fabricated_height(lv, other, supersample=1, n_levels=8).max() < 0.9 * want.max()
