import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def small_camera():
    """A small camera (1.08 mm aperture on a 200-pixel grid) that keeps optics tests fast."""
    import doefab

    return doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=5.4e-6, doe_pixels=200, sensor_pitch=5.4e-6,
                         sensor_distance=10e-3, focus_distance=5.0)


@pytest.fixture(scope="session")
def tiny_camera():
    """A 1.08 mm aperture on a 100-pixel grid at 10.8 µm: designs run in a second."""
    import doefab

    return doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                         sensor_distance=20e-3, focus_distance=5.0)


@pytest.fixture(scope="session")
def tiny_streak():
    return {"kernel_size": 31, "arm_px": 8}
