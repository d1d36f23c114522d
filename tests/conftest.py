import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


_MACHINE_DEVICE = os.environ.get("DOEFAB_DEVICE")
os.environ["DOEFAB_DEVICE"] = "cpu"  # tests and their shared fixtures compute on the CPU, where device=None ...


@pytest.fixture(autouse=True)
def _machine_device_when_marked_cuda(request, monkeypatch):
    """... unless a test is marked ``cuda``: it sees the machine's own default (on a GPU machine "auto" would
    otherwise move the networks of a test written for the CPU, or of a module's fixture, to the GPU)."""
    if request.node.get_closest_marker("cuda") is not None:
        if _MACHINE_DEVICE is None:
            monkeypatch.delenv("DOEFAB_DEVICE", raising=False)
        else:
            monkeypatch.setenv("DOEFAB_DEVICE", _MACHINE_DEVICE)


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


@pytest.fixture(scope="session")
def grating_design(tmp_path_factory):
    """``make(n, kernel, seed, n_bands=3) → design folder``: a quantized blazed grating over the coded half of an
    n-pixel aperture at 5.4 µm (``n_bands`` bands, the grating task's metric), plain (level 15) over the other
    half."""
    import numpy as np

    import doefab
    from doefab.design.design import Design
    from doefab.tasks.grating import GratingTask

    def make(n: int, kernel: int, seed: int = 0, n_bands: int = 3):
        pitch = 5.4e-6
        cam = doefab.Camera(aperture_diameter=n * pitch, doe_pitch=pitch, doe_pixels=n, sensor_pitch=5.4e-6,
                            sensor_distance=50e-3, focus_distance=5.0)
        task = GratingTask(kernel_size=kernel, n_bands=n_bands)
        task.bind(cam)
        lv = doefab.quantize_levels(task.init_height(cam, np.random.default_rng(seed)), cam)
        lv[:, n // 2:] = 15
        d = Design(task="grating", task_params=task.params(), camera=cam, wavelengths=task.wavelengths(cam),
                   depths=(5.0,), height=doefab.levels_to_height(lv, cam), levels=lv,
                   metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
        root = tmp_path_factory.mktemp("grating")
        d.save(root / "design")
        return root / "design"
    return make
