"""Radial parameterisation, the lens-difference start and the half-ring ring laws."""

import math

import numpy as np
import pytest
import torch

import doefab
from doefab.design.parameterization import RadialParam, lens_difference_waves, make_parameterization
from doefab.errors import DoefabError
from doefab.tasks import get_task


def _cam(n=64):
    return doefab.Camera(aperture_diameter=n * 5.4e-6, doe_pixels=n, doe_pitch=5.4e-6, focus_distance=3.5)


def test_radial_map_is_rotationally_symmetric_and_hits_its_knots():
    cam = _cam()
    p = RadialParam(cam, knots=9)
    knots = torch.linspace(0, 4, 9) ** 2
    w = p.waves(knots)
    assert torch.allclose(w, w.T) and torch.allclose(w, w.flip(0)) and torch.allclose(w, w.flip(1))
    # a pixel whose radius is exactly on a knot takes that knot's value; between knots, the linear blend
    c = (np.arange(64) - 31.5) * cam.doe_pitch
    r = np.hypot(c[None, :], c[:, None]) / (cam.aperture_diameter / 2)
    expected = np.interp(np.minimum(r, 1) * 8, np.arange(9), knots.numpy())
    assert np.allclose(w.numpy(), expected, atol=1e-5)


def test_lens_start_is_the_refocusing_lens():
    cam = _cam()
    task = get_task("half-ring")
    p = RadialParam(cam)
    w = p.waves(p.start(task, None, "lens")).double().numpy()
    full = lens_difference_waves(cam, task)
    inside = np.hypot(*np.meshgrid(np.arange(64) - 31.5, np.arange(64) - 31.5)) < 31
    # r²-profile, linearly interpolated between knots one pixel apart: error ≤ Δr² curvature / 8
    assert np.abs(w - full)[inside].max() < 0.01 * np.abs(full).max() + 1e-3


def test_the_lens_start_focuses_the_coded_half_at_the_farthest_depth():
    """Through the PSF pipeline (not the formula): the lens start's coded PSF peaks at 5 m, sharper there than at
    3 m or at the camera's own focus (3.5 m), and about as sharp as a half aperture in focus; its mirror image
    (the other sign) focuses nearer, not farther."""
    import torch

    from doefab.design.parameterization import theta_to_height

    cam = doefab.Camera(aperture_diameter=6e-3, doe_pitch=20e-6, doe_pixels=300, sensor_pitch=4e-6,
                        sensor_distance=50e-3, focus_distance=3.5)  # ~0.8 waves of defocus between 3.5 and 5 m
    task = get_task("half-ring")
    p = RadialParam(cam)
    with torch.no_grad():
        h = theta_to_height(p.waves(p.start(task, None, "lens")), cam).numpy()
        h_wrong = theta_to_height(-p.waves(p.start(task, None, "lens")), cam).numpy()
    depths = [3.0, 3.5, 5.0]
    peak = {}
    for name, height in (("lens", h), ("wrong sign", h_wrong), ("blank", None)):
        psf = doefab.split_aperture_psf(height, cam, [550e-9], depths, 31, halves=("coded",)).coded
        peak[name] = {z: float(psf[i, 0].max()) for i, z in enumerate(depths)}
    assert peak["lens"][5.0] > peak["lens"][3.5] > peak["lens"][3.0]
    assert peak["lens"][5.0] > 0.8 * peak["blank"][3.5]  # sharp: a half aperture in focus
    assert peak["wrong sign"][5.0] < 0.5 * peak["lens"][5.0]


def test_parameterization_names_are_checked():
    with pytest.raises(DoefabError, match="radial"):
        make_parameterization("zernike", _cam())
    with pytest.raises(DoefabError, match="radial parameterisation only"):
        make_parameterization("pixel", _cam(), knots=10)


def test_ring_laws():
    seed, focus = get_task("half-ring"), get_task("half-ring", ring_law="defocus")
    assert [seed.radius_px(z) for z in (1, 2, 3, 4, 5)] == [20, 15, 10, 5, 0]
    r = np.array([focus.radius_px(z) for z in (1.0, 1.25, 2.0, 5.0)])
    assert r[0] == pytest.approx(20) and r[-1] == pytest.approx(0)
    # linear in inverse depth, as a defocused aperture's blur radius is
    inv = 1 / np.array([1.0, 1.25, 2.0, 5.0])
    assert np.allclose(np.diff(r) / np.diff(inv), (r[0] - r[-1]) / (inv[0] - inv[-1]))
    with pytest.raises(DoefabError, match="ring law"):
        get_task("half-ring", ring_law="cubic")


def test_a_tiny_radial_design_runs_and_records_its_knots(tmp_path):
    cam = doefab.Camera.preset("depth").replace(doe_pixels=1600)
    d = doefab.optimize("half-ring", iterations=2, parameterization="radial", knots=50, sampling=4, progress=False,
                        task_params={"ring_law": "defocus", "z_step": 2.0})
    assert d.extra["config"]["parameterization"] == "radial" and len(d.extra["radial_knots_waves"]) == 50
    assert d.levels.shape == (cam.doe_pixels,) * 2
    # the 16-level map of a radial design is (up to quantization ties) rotationally symmetric on the coded half
    lv = d.levels[:, :800]
    assert (lv == lv[::-1]).mean() > 0.98
    assert not math.isnan(d.metrics["quantized"])


def test_a_radial_design_keeps_its_continuous_heights(tmp_path):
    """The knots in design.json rebuild the continuous heights, and quantizing them gives the stored levels."""
    from doefab.design.optimize import finalize_levels
    from doefab.tolerance.study import continuous_height

    d = doefab.optimize("half-ring", iterations=1, parameterization="radial", knots=30, sampling=4, progress=False,
                        task_params={"z_step": 2.0})
    d.save(tmp_path / "d")
    back = doefab.Design.load(tmp_path / "d")
    h = continuous_height(back)
    assert h is not None and np.array_equal(finalize_levels(h, back.camera), back.levels)


def test_the_half_ring_tasks_own_start_focuses_the_coded_half_at_the_farthest_depth():
    """``HalfRingTask.init_height`` (the pixel parameterisation's start) through the PSF pipeline: the coded PSF
    is sharpest at 5 m, and the opposite sign (its complement modulo 2π) focuses nearer."""
    cam = doefab.Camera(aperture_diameter=6e-3, doe_pitch=20e-6, doe_pixels=300, sensor_pitch=4e-6,
                        sensor_distance=50e-3, focus_distance=3.5)
    task = get_task("half-ring")
    h = task.init_height(cam, np.random.default_rng(0))
    h2pi = cam.material.height_2pi(cam.design_wavelength)
    wrong = np.mod(h2pi - h, h2pi)
    depths = [3.0, 3.5, 5.0]
    peak = {}
    for name, height in (("start", h), ("wrong sign", wrong)):
        psf = doefab.split_aperture_psf(height, cam, [550e-9], depths, 31, halves=("coded",)).coded
        peak[name] = {z: float(psf[i, 0].max()) for i, z in enumerate(depths)}
    assert peak["start"][5.0] > peak["start"][3.5] > peak["start"][3.0]
    assert peak["wrong sign"][5.0] < 0.5 * peak["start"][5.0]
