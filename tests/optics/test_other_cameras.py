"""The wave-optics PSFs follow geometric optics for cameras unlike the seed's prototype.

Two cameras built from scene keys: a short-focal-length, small-pixel one (8 mm f/2.8, 1.4 µm pixels, 2 µm DOE
pixels) and a long-focal-length one (135 mm f/8, 6 µm pixels, 10 µm DOE pixels). Each check compares the
computed PSF with a thin-lens expectation written out here: a blazed grating's first order at s·λ/Λ, a
defocused half aperture's blur radius D·s·|1/z − 1/z_f| / 2, and a cylindrical phase's streak half-length
(D/2)·s/f_c, all in that camera's sensor pixels.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from doefab.optics.psf import PSFPlan
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import scene_camera

CAMERAS = {
    "8mm-f2.8": dict(focal_length_mm=8.0, f_number=2.8, focus_distance_m=2.0, sensor_pitch_um=1.4, doe_pitch_um=2.0,
                     lens_f_number=2.0, near_m=0.3, period_px=32),
    "135mm-f8": dict(focal_length_mm=135.0, f_number=8.0, focus_distance_m=10.0, sensor_pitch_um=6.0,
                     doe_pitch_um=10.0, lens_f_number=2.0, near_m=5.0, period_px=16),
}


@pytest.fixture(scope="module", params=sorted(CAMERAS))
def camera(request, tmp_path_factory):
    c = CAMERAS[request.param]
    keys = "\n".join(f"{k} = {v}" for k, v in c.items() if k not in ("near_m", "period_px"))
    path = tmp_path_factory.mktemp("cam") / "scene.toml"
    path.write_text(f'task = "depth"\n[camera]\n{keys}\n')
    cam = scene_camera(load_scene(path))
    # the thin lens, independently: 1/s = 1/f − 1/z_f; the DOE aperture f / N
    f = c["focal_length_mm"] * 1e-3
    assert cam.sensor_distance == pytest.approx(1 / (1 / f - 1 / c["focus_distance_m"]), rel=1e-9)
    assert cam.aperture_diameter == pytest.approx(f / c["f_number"], rel=1e-9)
    assert cam.doe_pixels * cam.doe_pitch >= cam.aperture_diameter and cam.doe_pixels % 2 == 0
    return cam, c


def _grid(cam):
    n = cam.doe_pixels
    x = (np.arange(n) - (n - 1) / 2) * cam.doe_pitch
    return np.meshgrid(x, -x)  # columns: x (left to right); rows: y (top row largest)


def _two_pi_height(cam):
    lam = cam.design_wavelength
    return lam / (float(cam.material.index(np.array([lam]))[0]) - 1)


def test_a_blazed_grating_sends_its_first_order_to_s_lambda_over_period(camera):
    cam, c = camera
    period = c["period_px"] * cam.doe_pitch
    x, _ = _grid(cam)
    height = torch.from_numpy(_two_pi_height(cam) * np.mod(x / period, 1.0))
    lam = cam.design_wavelength  # the blaze sends all of it to one first order
    expect_px = cam.sensor_distance * lam / period / cam.sensor_pitch
    k = 2 * int(expect_px + 20) + 1
    with torch.no_grad():
        psf = PSFPlan(cam, [lam], [cam.focus_distance], k, halves=("coded",))(height).coded[0, 0].double().numpy()
    row, col = np.unravel_index(np.argmax(psf), psf.shape)
    assert row == k // 2
    # the spot's centroid in a small box around its peak: sub-pixel
    box = psf[row - 3:row + 4, col - 3:col + 4]
    cx = (box.sum(axis=0) * np.arange(col - 3, col + 4)).sum() / box.sum() - k // 2
    assert abs(abs(cx) - expect_px) < 0.35, (cx, expect_px)
    assert box.sum() > 0.6 * psf.sum()  # a blazed grating at its design wavelength: most light in that order


def test_a_defocused_half_aperture_blurs_to_radius_d_s_dioptres_over_two(camera):
    cam, c = camera
    z = c["near_m"]
    radius_px = cam.aperture_diameter * cam.sensor_distance * abs(1 / z - 1 / cam.focus_distance) / 2 / cam.sensor_pitch
    k = 2 * int(radius_px * 1.6) + 1
    with torch.no_grad():
        psf = PSFPlan(cam, [550e-9], [z], k, halves=("uncoded",))(None).uncoded[0, 0].double().numpy()
    yy, xx = np.mgrid[:k, :k] - k // 2
    # a uniform half disc of radius R about the chief ray has ⟨r²⟩ = R²/2
    measured = math.sqrt(2 * (psf * (xx**2 + yy**2)).sum() / psf.sum())
    assert radius_px > 15  # geometric blur dominates diffraction here
    assert measured == pytest.approx(radius_px, rel=0.08)
    # the uncoded half is x > 0: its half disc lies right of the centre column (its edge on the column)
    assert psf[:, k // 2 + 1:].sum() > 20 * psf[:, :k // 2].sum()


def test_a_cylindrical_phase_draws_a_streak_of_half_length_d_s_over_2f(camera):
    cam, c = camera
    half_len_px = 25.0
    f_c = (cam.aperture_diameter / 2) * cam.sensor_distance / (half_len_px * cam.sensor_pitch)
    lam = cam.design_wavelength
    _, y = _grid(cam)
    phase = np.mod(-math.pi * y**2 / (lam * f_c), 2 * math.pi)  # a cylinder lens of focal length f_c along y
    height = torch.from_numpy(_two_pi_height(cam) * phase / (2 * math.pi))
    k = 2 * int(half_len_px * 1.6) + 1
    with torch.no_grad():
        psf = PSFPlan(cam, [lam], [cam.focus_distance], k, halves=("coded",))(height).coded[0, 0].double().numpy()
    yy, xx = np.mgrid[:k, :k] - k // 2
    # along y the streak's density follows the half disc's chord, ∝ √(1 − (y/a)²): ⟨y²⟩ = a²/4
    a = 2 * math.sqrt((psf * yy**2).sum() / psf.sum())
    assert a == pytest.approx(half_len_px, rel=0.08)
    x_rms = math.sqrt((psf * xx**2).sum() / psf.sum())
    assert x_rms < 0.25 * a  # a streak, not a blob


def test_the_gratings_dispersion_follows_the_wavelength_and_the_tasks_targets_sit_on_it(camera):
    """At two wavelengths either side of the blaze the first order lands at s·tan(asin(λ/Λ)) (its spacing the
    dispersion across the band), and the grating task's target for each band (``GratingTask.targets`` bound to
    this camera) is the pixel where this camera's PSF puts the most light."""
    from doefab.tasks.grating import GratingTask

    cam, c = camera
    period = c["period_px"] * cam.doe_pitch
    x, _ = _grid(cam)
    height = torch.from_numpy(_two_pi_height(cam) * np.mod(x / period, 1.0))
    lams = [450e-9, 650e-9]
    expect = [cam.sensor_distance * math.tan(math.asin(lam / period)) / cam.sensor_pitch for lam in lams]
    k = 2 * int(max(expect) + 20) + 1
    with torch.no_grad():
        psf = PSFPlan(cam, lams, [cam.focus_distance], k, halves=("coded",))(height).coded[0].double().numpy()
    task = GratingTask(kernel_size=k, period_m=period, wavelengths_m=tuple(lams))
    task.bind(cam)
    targets = task.targets(cam).double().numpy()[0]  # [bands, K, K]: one pixel per band
    found = []
    for i, lam in enumerate(lams):
        p = psf[i]
        row, col = np.unravel_index(np.argmax(p), p.shape)
        box = p[row - 3:row + 4, col - 3:col + 4]
        found.append(abs((box.sum(axis=0) * np.arange(col - 3, col + 4)).sum() / box.sum() - k // 2))
        assert found[-1] == pytest.approx(expect[i], abs=0.4)
        t_row, t_col = np.unravel_index(np.argmax(targets[i]), targets[i].shape)
        assert (t_row, t_col) == (row, col), (lam, (t_row, t_col), (row, col))
    assert found[1] - found[0] == pytest.approx(expect[1] - expect[0], abs=0.6)  # the dispersion across the band


def test_defocus_blur_grows_with_the_dioptre_difference_and_the_ring_law_predicts_it(camera):
    """Two planes: the measured blur radius scales as |1/z − 1/z_f| for this aperture and sensor distance, and
    the defocus ring law's radius (``defocus_ring_px``, sharp at the focus distance) is the measured one."""
    from doefab.pipeline.system import defocus_ring_px

    cam, c = camera
    zs = [c["near_m"], 2 * c["near_m"] * cam.focus_distance / (c["near_m"] + cam.focus_distance)]  # ½ the dioptres
    dio = [abs(1 / z - 1 / cam.focus_distance) for z in zs]
    radius = cam.aperture_diameter * cam.sensor_distance * dio[0] / 2 / cam.sensor_pitch
    k = 2 * int(radius * 1.6) + 1
    with torch.no_grad():
        psf = PSFPlan(cam, [550e-9], zs, k, halves=("uncoded",))(None).uncoded[:, 0].double().numpy()
    yy, xx = np.mgrid[:k, :k] - k // 2
    measured = [math.sqrt(2 * (p * (xx**2 + yy**2)).sum() / p.sum()) for p in psf]
    assert measured[0] / measured[1] == pytest.approx(dio[0] / dio[1], rel=0.1)
    ring = defocus_ring_px(cam, {"planes_m": (zs[0], cam.focus_distance), "kernel_size": 10 * k})
    assert ring == pytest.approx(measured[0], rel=0.08)
