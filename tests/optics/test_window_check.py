"""A PSF window that cuts the plain half's defocus blur is refused by ``PSFPlan`` (``check=True``) and by
``doefab psf``, as scenes refuse it: the light past the window's edge would be missing from the PSFs. The blur is the
thin lens's by hand: an 8.64 mm aperture 50 mm from the sensor, focused at 5 m, blurs a point at 1 m into a disc of
8.64 mm × 50 mm × (1/1 m − 1/5 m) / 5.4 µm = 64 px across; each half's half disc reaches 32 px from the image."""

import pytest

import doefab
from doefab.cli import main

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
    assert "point at 1 m" in msg and "32.0 px" in msg and "31 px" in msg and "≥ 69 px" in msg, msg
    assert "check=False" in msg and "--kernel" in msg, msg
    doefab.PSFPlan(cam, [550e-9], [float("inf"), 1.0], 69)  # the window it names is taken


def test_an_accepted_cut_and_an_off_axis_window_are_computed():
    """``check=False`` accepts the cut PSFs; a window away from the axis holds whatever light reaches it (no
    blur check). The cut window holds less of the half's light than the one the refusal names."""
    cam = doefab.Camera(**COARSE)
    cut = doefab.PSFPlan(cam, [550e-9], [1.0], 63, halves=("uncoded",), check=False)(None).uncoded.sum()
    held = doefab.PSFPlan(cam, [550e-9], [1.0], 69, halves=("uncoded",))(None).uncoded.sum()
    assert float(cut) < float(held) - 1e-3
    doefab.PSFPlan(cam, [550e-9], [1.0], 63, halves=("uncoded",), center=(40 * cam.sensor_pitch, 0.0))


def test_doefab_psf_refuses_the_cut_window_before_any_output(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["psf", "--wavelengths-nm", "550", "--depths-m", "1", "--kernel", "63", "--out", str(out)]) == 2
    assert "≥ 69 px" in capsys.readouterr().err
    assert not out.exists()
