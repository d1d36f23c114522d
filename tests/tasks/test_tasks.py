"""Each task's target checked against its definition (independent arithmetic, not the code's numbers)."""

import math
import re

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


def test_streak_metric_counts_the_arms_not_the_spot_a_plain_half_focuses_to():
    """The metric is the arms' light: the ideal cross (4·arm + 1 equal pixels) scores the share of its pixels more than
    band_px = 1 from the centre, 4·(arm − 1) / (4·arm + 1); a plain coded half on the HDR camera (f/5.8: a spot of
    about a pixel at 5.4 µm) puts little on the arms. The cross with its centre counted would score that spot 0.96."""
    task = get_task("streak", kernel_size=31, arm_px=10)
    cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)  # the HDR aperture (8.64 mm) on a coarse grid
    ideal = task.metric(task.targets(cam), cam)["value"]
    assert ideal == pytest.approx(36 / 41)
    # arms counted by hand in the 31 px window (arm 10): width 0 → the 40 pixels off the centre; width 2 → two 5 × 25
    # strips (250) less their 5 × 5 overlap counted twice and the 5 × 5 centre (200); a band wider than the window → 0
    for band, want in ((0, 40), (2, 200), (16, 0)):
        assert float(get_task("streak", kernel_size=31, arm_px=10, band_px=band).band_masks(cam)[0, 0].sum()) == want
    flat = doefab.split_aperture_psf(None, cam, [589e-9], [cam.focus_distance], kernel_size=31).coded
    assert float(flat.sum()) > 0.45  # the window holds the spot's light
    frac = float(task.fractions(flat, cam)[0, 0])
    assert frac < 0.2
    k = np.arange(31) - 15
    centre = (np.abs(k)[:, None] <= 1) & (np.abs(k)[None, :] <= 1)
    assert float(flat[0, 0].numpy()[centre].sum()) / 0.5 > 0.7  # most of it in the 3 × 3 centre the metric leaves out


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
    (arm 20, band 1 in a 31 px window: 22 > 15; kernel ≥ 2·22 + 1 = 45, the least window that holds it); a
    grating's farthest first order s·λ/Λ/p + box + 2; a ring's largest radius + half-width + 1. The window each
    names holds its pattern, and the next smaller odd one does not."""
    from doefab.tasks.grating import GratingTask
    from doefab.tasks.halfring import HalfRingTask
    from doefab.tasks.streak import StreakTask

    with pytest.raises(DoefabError, match=r"reaches 22\.0 px .* 31 px window's 15: set kernel_size ≥ 45 or lower "
                                          r"arm_px"):
        doefab.optimize(StreakTask(kernel_size=31, arm_px=20), iterations=1, camera=tiny_camera, progress=False)
    assert StreakTask(kernel_size=31, arm_px=13).window_problem(tiny_camera) == ""  # 15: the edge fits
    assert StreakTask(kernel_size=31, arm_px=14).window_problem(tiny_camera) != ""

    cam = doefab.Camera.preset("hyperspectral")
    g = GratingTask(kernel_size=121)
    g.bind(cam)
    far = cam.sensor_distance * 700e-9 / (16 * 5.4e-6) / cam.sensor_pitch  # ~75 px, where the Fraunhofer model puts it
    assert g.pattern_reach_px(cam) == pytest.approx(far + 1 + 2, rel=1e-9)
    assert "kernel_size ≥" in g.window_problem(cam) and "period_m" in g.window_problem(cam)
    assert GratingTask(kernel_size=191).window_problem(cam) == ""

    cam = doefab.Camera.preset("depth")
    ring = HalfRingTask(kernel_size=63, ring_max_px=40.0)  # the nearest plane's ring: 40 px
    assert ring.pattern_reach_px(cam) == pytest.approx(40 + 1 + 1)
    assert "ring_max_px" in ring.window_problem(cam)
    assert HalfRingTask(kernel_size=63, ring_max_px=29.0).window_problem(cam) == ""

    for make, c in ((lambda k: StreakTask(kernel_size=k, arm_px=20), tiny_camera),
                    (lambda k: GratingTask(kernel_size=k), doefab.Camera.preset("hyperspectral")),
                    (lambda k: HalfRingTask(kernel_size=k, ring_max_px=40.0), cam),
                    (lambda k: HalfRingTask(kernel_size=k, ring_max_px=40.5), cam)):
        t = make(31)
        t.bind(c)
        need = t.window_for_pattern(c)
        assert make(need).fits_window(c) and not make(need - 2).fits_window(c)
        if isinstance(t, GratingTask):
            assert t.window_px(t.first_order_px(c)) == need


def test_a_steep_gratings_targets_sit_where_the_model_puts_its_light_and_a_steeper_one_is_refused():
    """A 4 µm period 2 mm in front of 7 µm pixels diffracts 550 nm by 7.9°: the Fraunhofer model puts its first
    order at s·λ/Λ = 39.29 px, a rectilinear lens at s·tan(asin(λ/Λ)) = 39.66 px, and the two round to different
    pixels. The task's target must be the pixel where the model's PSF of a blazed grating is brightest; at 650 nm
    (0.63 px apart) the task refuses the period and names one that the model holds."""
    from doefab.optics.psf import PSFPlan
    from doefab.tasks.grating import GratingTask, mapping_error_px

    cam = doefab.Camera(aperture_diameter=0.3e-3, doe_pitch=0.5e-6, doe_pixels=616, sensor_pitch=7e-6,
                        sensor_distance=2e-3, focus_distance=math.inf)
    period, lams, k = 8 * cam.doe_pitch, (500e-9, 550e-9, 600e-9), 101
    s, p = cam.sensor_distance, cam.sensor_pitch
    assert round(s * 550e-9 / period / p) != round(s * math.tan(math.asin(550e-9 / period)) / p)  # the case
    x = (np.arange(cam.doe_pixels) - (cam.doe_pixels - 1) / 2) * cam.doe_pitch
    two_pi = cam.design_wavelength / (float(cam.material.index(np.array([cam.design_wavelength]))[0]) - 1)
    height = torch.from_numpy(two_pi * np.mod(np.meshgrid(x, -x)[0] / period, 1.0))
    with torch.no_grad():
        psf = PSFPlan(cam, list(lams), [cam.focus_distance], k, halves=("coded",))(height).coded[0].numpy()
    task = GratingTask(kernel_size=k, period_m=period, wavelengths_m=lams)
    task.bind(cam)
    targets = task.targets(cam).numpy()[0]
    for band in range(len(lams)):
        assert np.argwhere(targets[band] > 0).tolist() == [list(np.unravel_index(psf[band].argmax(), (k, k)))]
    # the mapping error against the small-angle series s·(x³/2 + 3x⁵/8) / p
    xs = 650e-9 / period
    assert mapping_error_px(cam, 650e-9, period) == pytest.approx(s * (xs**3 / 2 + 3 * xs**5 / 8) / p, rel=2e-3)
    steep = GratingTask(kernel_size=k, period_m=period, wavelengths_m=(650e-9,))
    with pytest.raises(DoefabError, match=r"0\.63 px .* ≥ (\d+\.\d+) µm") as err:
        steep.bind(cam)
    fix = float(re.search(r"≥ (\d+\.\d+) µm", str(err.value)).group(1)) * 1e-6
    assert mapping_error_px(cam, 650e-9, fix) <= 0.5 < mapping_error_px(cam, 650e-9, fix - 0.01e-6)
    GratingTask(kernel_size=k, period_m=fix, wavelengths_m=(650e-9,)).bind(cam)
