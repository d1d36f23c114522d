"""A PSF window that cuts the plain half's defocus blur is refused by ``PSFPlan`` (``check=True``) and by
``doefab psf``, as scenes refuse it: the light past the window's edge would be missing from the PSFs. The blur is the
thin lens's by hand: an 8.64 mm aperture 50 mm from the sensor, focused at 5 m, blurs a point at 1 m into a disc of
8.64 mm × 50 mm × (1/1 m − 1/5 m) / 5.4 µm = 64 px across; each half's half disc reaches 32 px from the image."""

import math

import pytest

import doefab
from doefab.cli import main
from doefab.optics.camera import window_reach

COARSE = {"doe_pixels": 256, "doe_pitch": 33.75e-6}  # the 8.64 mm DOE on a quick grid (the blur does not change)


def test_the_blur_by_hand():
    cam = doefab.Camera(**COARSE)
    z, r = cam.widest_blur([float("inf"), 1.0, 5.0])
    assert z == 1.0 and r == pytest.approx(32.0)
    assert cam.widest_blur([float("inf")])[1] == pytest.approx(8.0)  # 1/5 m instead of 4/5 m
    assert not cam.window_holds_blur([1.0], 63) and cam.window_holds_blur([1.0], 65)
    assert cam.window_for_blur([1.0]) == 2 * (32 + 2) + 1  # an exact 32 px radius is not rounded up to 33


def test_a_window_that_cuts_the_blur_is_refused_with_the_window_that_holds_it():
    cam = doefab.Camera(**COARSE)
    with pytest.raises(doefab.DoefabError) as err:
        doefab.PSFPlan(cam, [550e-9], [float("inf"), 1.0], 63)
    msg = str(err.value)
    assert "point at 1 m" in msg and "32.0 px" in msg and "reaches 31 px" in msg and "≥ 69 px" in msg, msg
    assert "check=False" in msg and "task_params kernel_size" in msg and "--kernel" in msg, msg
    doefab.PSFPlan(cam, [550e-9], [float("inf"), 1.0], 69)  # the window it names is taken


def test_the_cut_window_loses_the_disc_s_edge_and_the_named_one_only_diffraction():
    """Wave optics against the geometric rule, at 656 nm: the 63 px window the rule refuses loses more than 2 % of
    the plain half's light (against a 141 px window), the 69 px one it names less than 1.6 % (diffraction's tails).
    ``check=False`` computes the cut PSFs; so does a window away from the axis (no blur check there)."""
    cam = doefab.Camera(**COARSE)

    def light(k):
        return float(doefab.PSFPlan(cam, [656e-9], [1.0], k, halves=("uncoded",), check=False)(None).uncoded.sum())

    whole = light(141)
    assert 1 - light(63) / whole > 0.02
    assert 1 - light(cam.window_for_blur([1.0])) / whole < 0.016
    doefab.PSFPlan(cam, [550e-9], [1.0], 63, halves=("uncoded",), center=(40 * cam.sensor_pitch, 0.0))


def test_an_even_window_reaches_one_pixel_less_and_the_coded_half_is_checked_too():
    """A star focused at 5 m blurs into a half disc of 8 px; a 17 px window (pixels −8 … 8) holds it, a 16 px one
    (−8 … 7) does not. The design's coded-only plans are checked as well (the blank coded half blurs alike)."""
    cam = doefab.Camera(**COARSE)
    assert window_reach(17) == 8 and window_reach(16) == 7
    doefab.PSFPlan(cam, [550e-9], [float("inf")], 17)
    for halves in (("coded", "uncoded"), ("coded",)):
        with pytest.raises(doefab.DoefabError, match="the 16 px PSF window reaches 7 px"):
            doefab.PSFPlan(cam, [550e-9], [float("inf")], 16, halves=halves)


def test_doefab_demo_takes_only_windows_that_hold_its_planes_blur_and_its_gratings_orders(tmp_path, capsys):
    """The demo's planes (5 m, infinity, 2 m on the default camera): the 2 m point blurs into a 12 px half disc,
    which a 29 px window holds (2 px of room); its test grating (16 DOE pixels of 5.4 µm, 50 mm before 5.4 µm
    pixels) sends 656 nm s·λ/Λ/p = 70.3 px off axis, which with the 3 × 3 box and 2 px needs 2·⌈73.3⌉ + 1 = 149."""
    assert doefab.Camera().window_for_blur([5.0, float("inf"), 2.0]) == 29
    far = 0.05 * 656e-9 / (16 * 5.4e-6) / 5.4e-6
    assert 2 * math.ceil(far + 1 + 2) + 1 == 149
    from doefab.cli.demo import MIN_KERNEL, min_kernel

    assert min_kernel(doefab.Camera()) == MIN_KERNEL == 149  # the parser's constant is the camera's computation
    for k in ("27", "147"):
        with pytest.raises(SystemExit):
            main(["demo", "--kernel", k, "--out", str(tmp_path / "d")])
        assert "≥ 149" in capsys.readouterr().err


def test_doefab_psf_refuses_the_cut_window_before_any_output(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["psf", "--wavelengths-nm", "550", "--depths-m", "1", "--kernel", "63", "--out", str(out)]) == 2
    assert "≥ 69 px" in capsys.readouterr().err
    assert not out.exists()
