"""The aperture-stop sentence of the reports (issue 37): its words agree with the numbers it prints: diameters
within 1 % are "about equal", others printed with the decimals that tell them apart."""

import math
import re

import pytest

import doefab
from doefab.tolerance.mounted import STOP_TOLERANCE, stop_case


def _camera(doe_mm: float, pupil_mm: float, sensor_distance: float = 50e-3):
    cam = doefab.Camera(aperture_diameter=doe_mm * 1e-3, doe_pitch=5.4e-6, sensor_distance=sensor_distance,
                        doe_pixels=math.ceil(doe_mm * 1e-3 / 5.4e-6) + 2)
    return cam.replace(lens_f_number=cam.focal_length * 1e3 / pupil_mm)


@pytest.mark.parametrize("doe_mm,pupil_mm,distance", [
    (8.93, 8.94, 50e-3), (8.94, 8.93, 50e-3), (8.75, 8.80, 50e-3), (8.64, 27.5, 50e-3), (8.0, 8.85, 50e-3),
    (9.3, 8.85, 50e-3), (0.6, 0.6045, 10e-3), (0.6, 0.61, 10e-3), (0.61, 0.6, 10e-3), (2.531792, 2.531792, 4.4e-3)])
def test_the_stop_sentence_agrees_with_the_numbers_it_prints(doe_mm, pupil_mm, distance):
    cam = _camera(doe_mm, pupil_mm, distance)
    text = stop_case(cam)
    doe = float(re.search(r"the DOE's ([\d.]+) mm baffle", text).group(1))
    pupil = float(re.search(r"the lens's ([\d.]+) mm entrance pupil", text).group(1))
    assert doe == pytest.approx(doe_mm, abs=0.006) and pupil == pytest.approx(pupil_mm, abs=0.006)
    if abs(doe_mm - pupil_mm) <= STOP_TOLERANCE * max(doe_mm, pupil_mm):
        assert "about equal" in text and "narrower" not in text
        assert ("takes the baffle as the aperture stop" in text) == cam.doe_is_stop
    elif cam.doe_is_stop:
        assert "baffle is narrower than the lens's" in text and doe < pupil, text
    else:
        assert "entrance pupil (f/" in text and "is narrower than the DOE's" in text and pupil < doe, text



def test_equal_diameters_print_with_two_decimals():
    """A lens at the baffle's f-number (a phone camera wide open: 4.38 mm at f/1.73) prints both as 2.53 mm, not
    to the six decimals that only diameters differing in the sixth need."""
    cam = doefab.Camera(aperture_diameter=4.38e-3 / 1.73, doe_pitch=4e-6, sensor_distance=4.4e-3, doe_pixels=636)
    text = stop_case(cam.replace(lens_f_number=cam.focal_length / cam.aperture_diameter))
    assert "the DOE's 2.53 mm baffle and the lens's 2.53 mm entrance pupil" in text, text
