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
