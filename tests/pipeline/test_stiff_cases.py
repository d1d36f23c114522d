"""Stiff and extreme cases (issue: scene pipeline): the nearest point the routes accept, both ends of
300–1100 nm, and float32 against float64 where the phase step sits just under its limit."""

import math

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import SamplingError
from doefab.optics.psf import SOURCE_PHASE_LIMIT
from doefab.optics.pupil import source_path_difference


def _phase_step(cam, z, lam):
    """Largest source-phase change between pupil samples one DOE pitch apart along a radius (independent)."""
    r = np.arange(0, cam.aperture_diameter / 2 + cam.doe_pitch, cam.doe_pitch)
    return float(np.max(np.abs(np.diff(source_path_difference(r**2, z, cam.focus_distance)))) * 2 * math.pi / lam)


def _nearest_accepted(cam, lam):
    lo, hi = 1e-3, 10.0  # bisection on the step = limit condition
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if _phase_step(cam, mid, lam) > SOURCE_PHASE_LIMIT else (lo, mid)
    return hi


def test_nearest_depth_boundary_and_precision_there(small_camera):
    lam = 450e-9
    z0 = _nearest_accepted(small_camera, lam)
    assert 0.005 < z0 < 5
    with pytest.raises(SamplingError, match="pupil_oversample"):
        doefab.PSFPlan(small_camera, [lam], [0.8 * z0], 63)
    z = 1.05 * z0  # phase step just under the limit
    assert 0.85 * SOURCE_PHASE_LIMIT < _phase_step(small_camera, z, lam) < SOURCE_PHASE_LIMIT
    psf = {}
    for prec in ("float32", "float64"):
        with torch.no_grad():
            psf[prec] = doefab.PSFPlan(small_camera, [lam], [z], 151, precision=prec)(None).coded.double()
    assert bool(torch.isfinite(psf["float32"]).all())
    assert float((psf["float32"] - psf["float64"]).norm() / psf["float64"].norm()) < 1e-3
    # a strongly defocused half still carries its half of the light (inside a large window)
    assert float(psf["float64"].sum()) == pytest.approx(0.5, abs=0.03)


@pytest.mark.parametrize("lam", [300e-9, 1100e-9])
def test_wavelength_extremes(small_camera, lam):
    psf = {}
    for prec in ("float32", "float64"):
        with torch.no_grad():
            psf[prec] = doefab.PSFPlan(small_camera, [lam], [5.0], 101, precision=prec)(None).coded.double()
    assert float(psf["float64"].sum()) == pytest.approx(0.5, abs=0.02)
    assert float((psf["float32"] - psf["float64"]).norm() / psf["float64"].norm()) < 1e-4
    # the Airy core scales with λ: the first zero of the full aperture at 1.22 λ s / D
    first_zero = 1.22 * lam * small_camera.sensor_distance / small_camera.aperture_diameter
    assert first_zero > small_camera.sensor_pitch * (0.5 if lam < 500e-9 else 2)


def test_doctor_fails_a_crosstalk_calibration_that_cannot_separate_the_views(tmp_path):
    """At 45 % crosstalk each way, ±2 % across the sensor, the determinant at the calibrated edge of the centre row
    is 1 − 0.47 − 0.43 = 0.10, and the sensor's worst pixel (its spots widen toward the corners, its rows scatter)
    a little less, 0.084: it passes. At 48.5 % the pixel's is below 0.05: the doctor must say so and how to fix it.
    The doctor's value is the least 1 − α_l→r − α_r→l of the sensor's ratio maps, found here over every row and
    257 columns (``test_crosstalk_sensor`` checks the maps and the corner against the model's law)."""
    import numpy as np

    from doefab.imaging.sensorcrosstalk import SensorCrosstalk
    from doefab.pipeline.doctor import diagnose
    from doefab.pipeline.scene import load_scene

    rows = {}
    for pct in (45.0, 48.5):
        budget = tmp_path / f"b{pct}.toml"
        budget.write_text(f"[sensor]\ncrosstalk_lr_percent = {pct}\ncrosstalk_rl_percent = {pct}\n"
                          "crosstalk_slope_percent = 2.0\n")
        scene_file = tmp_path / f"s{pct}.toml"
        scene_file.write_text(open("scenes/hdr.toml").read().replace('budget = "default"', f'budget = "{budget}"'))
        checks = [r for r in diagnose(load_scene(scene_file), precision_check=False) if "crosstalk" in r["check"]]
        rows[pct] = checks[0]
        sensor = SensorCrosstalk((pct / 100, pct / 100), 0.02)
        a, b = sensor.ratios(np.arange(3072) - 1535.5, np.linspace(-1536, 1536, 257), session=None)
        brute = float((1 - a - b).min())
        assert rows[pct]["value"] == pytest.approx(brute, abs=2e-3)
        assert rows[pct]["value"] < 1 - 2 * pct / 100  # below the budget's own worst column (the corners)
    assert rows[45.0]["ok"] and rows[45.0]["value"] > 0.05
    assert not rows[48.5]["ok"] and rows[48.5]["value"] < 0.05 and rows[48.5]["fix"]