"""Each task's target checked against its definition (independent arithmetic, not the code's numbers)."""

import math

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError
from doefab.tasks import get_task


def test_streak_target_is_a_cross_summing_to_half():
    task = get_task("streak", kernel_size=31, arm_px=10)
    cam = doefab.Camera.preset("hdr")
    tg = task.targets(cam)[0, 0].numpy()
    assert tg.sum() == pytest.approx(0.5)
    on = np.argwhere(tg > 0)
    c = 15
    assert all((r == c and abs(col - c) <= 10) or (col == c and abs(r - c) <= 10) for r, col in on)
    assert len(on) == 2 * 21 - 1
    assert np.allclose(tg[tg > 0], 0.5 / 41)


def test_grating_spots_follow_the_grating_equation():
    task = get_task("grating")
    cam = doefab.Camera.preset("hyperspectral")
    task.bind(cam)
    tg = task.targets(cam)[0].numpy()
    lams = np.linspace(400e-9, 700e-9, 31)
    assert tg.shape[0] == 31
    for w, lam in enumerate(lams):
        assert tg[w].sum() == pytest.approx(0.5)
        r, col = np.argwhere(tg[w] > 0)[0]
        expected = 0.05 * math.tan(math.asin(lam / (16 * 5.4e-6))) / 5.4e-6
        assert r == task.kernel_size // 2
        assert abs((col - task.kernel_size // 2) - expected) <= 0.5
    # about one pixel per 10 nm (seed 4.4)
    step = np.diff([np.argwhere(tg[w] > 0)[0][1] for w in range(31)])
    assert 0.5 <= step.mean() <= 1.5


def test_half_ring_radii_are_25_minus_5z():
    task = get_task("half-ring")
    cam = doefab.Camera.preset("depth")
    depths = task.depths(cam)
    assert len(depths) == 17 and depths[0] == 1.0 and depths[-1] == 5.0
    tg = task.targets(cam)[:, 0].numpy()
    c = task.kernel_size // 2
    for d, z in enumerate(depths):
        assert tg[d].sum() == pytest.approx(0.5)
        pts = np.argwhere(tg[d] > 0)
        x = pts[:, 1] - c
        y = c - pts[:, 0]
        r = 25 - 5 * z
        assert np.all(np.abs(np.hypot(x, y) - r) <= 0.5 + 1e-9)
        if r > 0:
            assert np.all(x <= 0)  # the arc lies on the x <= 0 side: it opens toward +x
            assert {(0, int(round(r))), (0, -int(round(r)))} <= set(zip(x.tolist(), y.tolist())) or r % 1
        else:
            assert pts.tolist() == [[c, c]]


def test_metric_counts_light_outside_the_window_as_lost():
    task = get_task("half-ring")
    cam = doefab.Camera.preset("depth")
    psf = task.targets(cam).clone() * 0.5  # half the coded light in the band, the rest "outside the window"
    m = task.metric(psf, cam)
    assert m["value"] == pytest.approx(0.5) and m["worst"] == pytest.approx(0.5)


def test_unknown_task_and_bad_params():
    with pytest.raises(DoefabError, match="unknown task"):
        get_task("blur")
    with pytest.raises(DoefabError, match="bad parameters"):
        get_task("streak", arm=3)


def test_window_loss_weighs_the_worst_entry():
    task = get_task("half-ring", loss_kind="window")
    even = torch.tensor([0.5, 0.5, 0.5, 0.5])
    uneven = torch.tensor([0.6, 0.6, 0.6, 0.2])  # same mean, one bad depth
    assert float(task.loss_from_fractions(uneven)) > float(task.loss_from_fractions(even)) + 0.25
    band = get_task("half-ring", loss_kind="band")
    assert float(band.loss_from_fractions(uneven)) == pytest.approx(float(band.loss_from_fractions(even)))


def test_a_pattern_past_the_window_is_refused_by_optimize_not_cut(tiny_camera):
    """A target drawn past the window's edge would be silently cut (its arm, first order or ring outside the PSF):
    ``optimize`` refuses it, naming the window that holds it. Reaches written out: a streak's arm + band + 1 px
    (arm 20, band 1 in a 31 px window: 22 > 15; kernel ≥ 2·23 + 1 = 47); a grating's farthest first order
    s·tan(asin(λ/Λ))/p + box + 2; a ring's largest radius + half-width + 1."""
    from doefab.tasks.grating import GratingTask
    from doefab.tasks.halfring import HalfRingTask
    from doefab.tasks.streak import StreakTask

    with pytest.raises(DoefabError, match=r"reaches 22\.0 px .* 31 px window's 15: set kernel_size ≥ 47 or lower "
                                          r"arm_px"):
        doefab.optimize(StreakTask(kernel_size=31, arm_px=20), iterations=1, camera=tiny_camera, progress=False)
    assert StreakTask(kernel_size=31, arm_px=13).window_problem(tiny_camera) == ""  # 15: the edge fits
    assert StreakTask(kernel_size=31, arm_px=14).window_problem(tiny_camera) != ""

    cam = doefab.Camera.preset("hyperspectral")
    g = GratingTask(kernel_size=121)
    g.bind(cam)
    far = cam.sensor_distance * math.tan(math.asin(700e-9 / (16 * 5.4e-6))) / cam.sensor_pitch  # ~75 px
    assert g.pattern_reach_px(cam) == pytest.approx(far + 1 + 2, rel=1e-9)
    assert "kernel_size ≥" in g.window_problem(cam) and "period_m" in g.window_problem(cam)
    assert GratingTask(kernel_size=191).window_problem(cam) == ""

    cam = doefab.Camera.preset("depth")
    ring = HalfRingTask(kernel_size=63, ring_max_px=40.0)  # the nearest plane's ring: 40 px
    assert ring.pattern_reach_px(cam) == pytest.approx(40 + 1 + 1)
    assert "ring_max_px" in ring.window_problem(cam)
    assert HalfRingTask(kernel_size=63, ring_max_px=29.0).window_problem(cam) == ""
