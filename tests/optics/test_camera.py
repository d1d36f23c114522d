import math

import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError


def test_defaults_are_the_prototype():
    cam = doefab.Camera()
    assert cam.aperture_diameter == 8.64e-3 and cam.doe_pixels == 1600 and cam.doe_pitch == 5.4e-6
    assert cam.sensor_distance == 50e-3 and cam.focus_distance == 5.0 and cam.sensor_pitch == 5.4e-6
    # thin lens: 1/f = 1/s + 1/z
    assert cam.focal_length == pytest.approx(1 / (1 / 0.05 + 1 / 5.0), rel=1e-12)
    assert doefab.Camera(focus_distance=math.inf).focal_length == pytest.approx(0.05)


def test_presets():
    hdr = doefab.Camera.preset("hdr")
    assert (hdr.doe_pixels, hdr.doe_pitch) == (3200, 2.7e-6)
    assert doefab.Camera.preset("depth").focus_distance == 3.5
    assert doefab.Camera.preset("hyperspectral").doe_pixels == 1600
    with pytest.raises(DoefabError, match="unknown camera preset"):
        doefab.Camera.preset("nope")


def test_replace_and_round_trip():
    cam = doefab.Camera().replace(focus_distance=2.0)
    assert cam.focus_distance == 2.0
    assert doefab.Camera.from_dict(cam.to_dict()) == cam
    inf = doefab.Camera(focus_distance=math.inf)
    assert doefab.Camera.from_dict(inf.to_dict()) == inf


@pytest.mark.parametrize("kw, msg", [
    ({"doe_pixels": 1000}, "smaller than the aperture"),
    ({"doe_pitch": 0.0}, "doe_pitch must be a positive"),
    ({"sensor_distance": -1.0}, "sensor_distance must be a positive"),
    ({"aperture_diameter": float("nan")}, "aperture_diameter"),
    ({"focus_distance": 0.0}, "focus_distance"),
    ({"doe_pixels": 1600.0}, "integer"),
])
def test_inconsistent_cameras_refused(kw, msg):
    with pytest.raises(DoefabError, match=msg):
        doefab.Camera(**kw)


def test_a_macro_lens_at_life_size_is_a_camera():
    """A 100 mm lens focused at 0.2 m images 1:1 (sensor 0.2 m behind it: 1/f = 1/s + 1/z); at 0.15 m it
    magnifies 2× (s = 0.3 m). Both images are real."""
    one = doefab.Camera(sensor_distance=0.2, focus_distance=0.2, aperture_diameter=10e-3, doe_pixels=2000,
                        doe_pitch=5e-6)
    assert one.focal_length == pytest.approx(0.1, rel=1e-12)
    two = doefab.Camera(sensor_distance=0.3, focus_distance=0.15, aperture_diameter=10e-3, doe_pixels=2000,
                        doe_pitch=5e-6)
    assert two.focal_length == pytest.approx(0.1, rel=1e-12) and two.f_number == pytest.approx(30.0)


def test_fused_silica_sellmeier():
    n = doefab.FUSED_SILICA.index(550e-9)
    assert n == pytest.approx(1.45991, abs=2e-5)  # DESIGN-NOTES value
    # independent: Malitson's published index at the sodium D line (587.6 nm) is 1.4585
    assert doefab.FUSED_SILICA.index(587.6e-9) == pytest.approx(1.4585, abs=1e-4)
    assert doefab.FUSED_SILICA.height_2pi(550e-9) == pytest.approx(1.196e-6, rel=1e-3)
    assert np.all(np.diff(doefab.FUSED_SILICA.index(np.linspace(400e-9, 700e-9, 31))) < 0)  # normal dispersion
