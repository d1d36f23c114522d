"""A DOE in front of the aperture plane: checked against the Talbot effect, geometric walk-off across the split
line, energy conservation and the gap → 0 limit."""

import math

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError
from doefab.optics.gap import gap_transmittance

LAM = 550e-9


def _cam(n=512):
    return doefab.Camera(aperture_diameter=n * 5.4e-6, doe_pixels=n, doe_pitch=5.4e-6)


def _coded_half(cam, phase_of_x):
    """Heights (metres) whose phase at LAM is phase_of_x(x) on the coded (x < 0) half and 0 on the plain one."""
    n = cam.doe_pixels
    x = (np.arange(n) - (n - 1) / 2) * cam.doe_pitch
    dn = float(cam.material.index(LAM)) - 1
    row = np.where(x < 0, phase_of_x(x) / (2 * math.pi / LAM * dn), 0.0)
    return torch.from_numpy(np.tile(row, (n, 1)))


def _interior(cam, margin_px):
    n = cam.doe_pixels
    c = (np.arange(n) - (n - 1) / 2)
    r = np.hypot(c[None, :], c[:, None])
    return (r < n / 2 - margin_px) & (c[None, :] < -margin_px)


def test_talbot_self_image_and_half_period_shift():
    """A periodic phase grating lit by a plane wave images itself at z_T = 2Λ²/λ (Talbot) and, shifted by half a
    period, at z_T/2: an analytic result independent of the code's propagation."""
    cam = _cam(768)
    period = 8 * cam.doe_pitch
    grating = lambda x: 1.0 * np.sin(2 * math.pi * x / period)  # noqa: E731 - weak harmonics: paraxial Talbot
    h = _coded_half(cam, grating)
    zt = 2 * period**2 / LAM
    inner = torch.from_numpy(_interior(cam, 100))  # past the edges' Fresnel ripples
    t0 = gap_transmittance(h, cam, LAM, math.inf, 0.0)
    tt = gap_transmittance(h, cam, LAM, math.inf, zt)
    assert float((tt - t0).abs()[inner].max()) < 0.02
    th = gap_transmittance(h, cam, LAM, math.inf, zt / 2)
    shifted = torch.roll(t0, 4, dims=1)
    assert float((th - shifted).abs()[inner].max()) < 0.02
    assert float((th - t0).abs()[inner].max()) > 1.0  # the half-period shift is a real change


def test_tilted_light_walks_across_the_split_line():
    """A blazed (linear) phase on the coded half tilts its light by θ = λ/Λ towards +x; over a gap g it crosses the
    split line in a strip of width g·θ: the plain half gains, and the coded half loses, that strip's light
    (geometric optics), and the tilted light stays tilted (its first order lands at f·θ on the sensor)."""
    cam = _cam(256)
    period = 4 * cam.doe_pitch
    h = _coded_half(cam, lambda x: np.mod(2 * math.pi * x / period, 2 * math.pi))
    gap = 5e-3
    t = gap_transmittance(h, cam, LAM, math.inf, gap)
    n = cam.doe_pixels
    c = np.arange(n) - (n - 1) / 2
    disk = torch.from_numpy(np.hypot(c[None, :], c[:, None]) < n / 2)
    plain = disk & torch.from_numpy(np.broadcast_to(c[None, :] > 0, (n, n)).copy())
    coded = disk & ~plain
    excess = (t.abs() ** 2 - 1)
    gained = float(excess[plain].sum() / disk.sum())
    lost = -float(excess[coded].sum() / disk.sum())
    radius = n / 2 * cam.doe_pitch
    strip = (2 * radius * gap * LAM / period) / (math.pi * radius**2)  # strip area / aperture area
    assert gained == pytest.approx(strip, rel=0.15)
    assert lost == pytest.approx(strip, rel=0.15)
    # the plain half's PSF now holds tilted light around u = f·θ (sensor pixels to the right of the axis)
    plan = doefab.PSFPlan(cam, [LAM], [math.inf], kernel_size=151, center=(cam.focal_length * LAM / period, 0.0))
    p0, pg = plan(h), plan(h, gap=gap)
    assert float(pg.uncoded.sum() - p0.uncoded.sum()) == pytest.approx(strip, rel=0.2)


def test_zero_gap_limit_and_blank_doe():
    cam = _cam(128)
    rng = np.random.default_rng(1)
    h = _coded_half(cam, lambda x: 0 * x) + torch.from_numpy(rng.uniform(0, 1e-6, (128, 128))) * 0
    h[:, :64] = torch.from_numpy(rng.integers(0, 16, (128, 64)) * 7.5e-8)
    plan = doefab.PSFPlan(cam, [LAM, 650e-9], [2.0, math.inf], kernel_size=31)
    p0, pe = plan(h), plan(h, gap=1e-12)
    assert torch.allclose(pe.coded, p0.coded, atol=1e-6, rtol=0)
    assert torch.allclose(pe.uncoded, p0.uncoded, atol=1e-6, rtol=0)
    flat = torch.zeros(128, 128, dtype=torch.float64)
    pb, pf = plan(flat, gap=5e-3), plan(flat)
    # to rounding in every pixel, the window's faint edges too (a blank DOE is a flat plate at any gap)
    assert torch.allclose(pb.coded, pf.coded, atol=1e-12, rtol=1e-5)
    assert torch.allclose(pb.uncoded, pf.uncoded, atol=1e-12, rtol=1e-5)


def test_heights_outside_the_clear_aperture_change_nothing():
    """No light passes outside the clear aperture: a flat DOE with a bump there (in the aperture plane) is still a
    flat plate."""
    cam = _cam(128)
    plan = doefab.PSFPlan(cam, [LAM], [math.inf], kernel_size=63)
    flat = torch.zeros(128, 128, dtype=torch.float64)
    bumped = flat.clone()
    bumped[0, 0] = 1e-7  # a grid corner: beyond the clear aperture's circle
    assert torch.equal(plan(bumped).coded, plan(flat).coded)


def test_energy_is_conserved_over_the_gap():
    cam = _cam(256)
    rng = np.random.default_rng(2)
    h = torch.zeros(256, 256, dtype=torch.float64)
    blocks = rng.integers(0, 16, (16, 8)) * 7.5e-8  # 16-pixel blocks: small angles, little light leaves the grid
    h[:, :128] = torch.from_numpy(np.kron(blocks, np.ones((16, 16))))
    t = gap_transmittance(h, cam, LAM, 3.0, 4e-3)
    inside = torch.from_numpy(_interior(cam, 0) | (np.hypot(*np.meshgrid(np.arange(256) - 127.5,
                                                                          np.arange(256) - 127.5)) < 128))
    # |t|² averages to 1 over the clear aperture: light is moved, not made (a little leaves past the rim)
    mean = float((t.abs() ** 2)[inside].mean())
    assert mean == pytest.approx(1.0, abs=0.01)


def test_gap_in_wrong_units_is_refused():
    cam = _cam(64)
    plan = doefab.PSFPlan(cam, [LAM], [math.inf], kernel_size=15)
    with pytest.raises(DoefabError, match="metres"):
        plan(torch.zeros(64, 64), gap=5.0)
