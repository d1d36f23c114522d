"""A task's pattern in its PSF window: the scene check (``doefab doctor``) refuses exactly the scenes whose task
``optimize`` refuses (``Task.window_problem``), at the edge of the window; a depth scene on another camera gets a
default ring that fits with the ring's width it asks for."""

import math

import pytest

import doefab
from doefab.errors import DoefabError
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve
from doefab.tasks import get_task


def _resolve(tmp_path, task: str, design: str, camera: str = ""):
    p = tmp_path / "scene.toml"
    p.write_text(f'task = "{task}"\nstages = ["design"]\n[camera]\n{camera}[design]\n{design}')
    return resolve(load_scene(p))


@pytest.mark.parametrize("task, design, params, fits", [
    # the HDR scene's 95 px window holds 47 px: arms + the 1 px band + 1 px
    ("hdr", "streak_arm_px = 45\n", {"kernel_size": 95, "arm_px": 45}, True),
    ("hdr", "streak_arm_px = 46\n", {"kernel_size": 95, "arm_px": 46}, False),
    # the depth scene's 63 px window holds 31 px: the nearest plane's ring + its 1 px half-width + 1 px
    ("depth", "ring_max_px = 29\n", {"kernel_size": 63, "ring_max_px": 29.0}, True),
    ("depth", "ring_max_px = 29.5\n", {"kernel_size": 63, "ring_max_px": 29.5}, False),
])
def test_doctor_and_optimize_refuse_the_same_patterns(tmp_path, task, design, params, fits):
    name = {"hdr": "streak", "depth": "half-ring"}[task]
    if fits:
        res = _resolve(tmp_path, task, design)
        assert res.task.window_problem(res.camera) == ""
        assert res.task.pattern_reach_px(res.camera) == pytest.approx(res.task.kernel_size // 2)  # at the edge
        return
    with pytest.raises(DoefabError, match="does not fit optics.kernel_px"):
        _resolve(tmp_path, task, design)
    cam = doefab.Camera.preset(task)
    t = get_task(name, **params)
    assert t.window_problem(cam)  # the same task in the API: refused by optimize
    with pytest.raises(DoefabError, match="kernel_size ≥"):
        doefab.optimize(t, iterations=1, camera=cam, progress=False)


def test_a_grating_past_its_window_is_refused_by_optimize_naming_the_window():
    """The hyperspectral preset's 700 nm first order lands s·λ/Λ/p ≈ 75 px off axis at Λ = 16 × 5.4 µm (where the
    Fraunhofer model puts it): a 121 px window (60 px) cannot hold it with its 1 px box and 2 px; the least window
    that does is 2·⌈far + 3⌉ + 1."""
    from doefab.tasks.grating import GratingTask

    cam = doefab.Camera.preset("hyperspectral")
    far = cam.sensor_distance * 700e-9 / (16 * 5.4e-6) / cam.sensor_pitch
    with pytest.raises(DoefabError, match=f"kernel_size ≥ {2 * math.ceil(far + 3) + 1} or a longer period_m"):
        doefab.optimize(GratingTask(kernel_size=121), iterations=1, camera=cam, progress=False)


def test_the_default_ring_on_another_camera_fits_the_ring_width_asked(tmp_path):
    """A 35 mm f/4 lens on 3.76 µm pixels blurs the nearest plane far beyond the 63 px window, so the scene's
    default ring is capped to the window with 1 px to spare: with design.ring_width_px = 3 at 31 − 2 − 3 = 26 px
    (28 before, which the window check then refused, naming a ring_max_px the scene never set)."""
    camera = "focal_length_mm = 35.0\nf_number = 4.0\nlens_f_number = 2.0\nsensor_pitch_um = 3.76\n"
    res = _resolve(tmp_path, "depth", "ring_width_px = 3\n", camera)
    assert res.task.ring_max_px == 26.0 and res.task.window_problem(res.camera) == ""
    assert _resolve(tmp_path, "depth", "", camera).task.ring_max_px == 28.0  # 1 px half-width: 31 − 2 − 1
