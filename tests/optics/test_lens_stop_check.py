"""A camera whose lens pupil is narrower than the DOE's baffle is refused by ``PSFPlan`` (``check=True``), as scenes
refuse it (``pipeline.sampling.stop_checks``). By hand: the default camera's lens has f = 1 / (1/50 mm + 1/5 m)
= 49.505 mm; at f/8 its entrance pupil is 6.19 mm, against the 8.64 mm baffle; the widest f-number that holds the
baffle is 49.505 / 8.64 = 5.729."""

import pytest

import doefab

COARSE = {"doe_pixels": 256, "doe_pitch": 33.75e-6}  # the 8.64 mm DOE on a quick grid


def _plan(cam, **kw):
    return doefab.PSFPlan(cam, [550e-9], [float("inf")], 33, **kw)


def test_a_lens_narrower_than_the_baffle_is_refused_with_fixes_that_pass():
    cam = doefab.Camera(lens_f_number=8.0, **COARSE)
    assert cam.focal_length == pytest.approx(1 / (1 / 50e-3 + 1 / 5.0))
    with pytest.raises(doefab.DoefabError) as err:
        _plan(cam)
    msg = str(err.value)
    assert "6.19 mm entrance pupil" in msg and "8.64 mm baffle" in msg, msg
    assert "aperture_diameter ≤ 0.006188 m" in msg and "(≤ 5.729 holds this DOE)" in msg, msg
    assert "check=False" in msg, msg
    _plan(cam.replace(aperture_diameter=0.006188))  # the DOE made the stop
    _plan(cam.replace(lens_f_number=5.729))  # the lens opened to the baffle
    psf = _plan(cam, check=False)(None)  # accepted on request: the PSFs over the whole baffle
    assert float(psf.uncoded.sum()) > 0


def test_about_equal_diameters_are_modelled_and_the_prototype_lens_is_wider():
    """Within 1 % (``STOP_TOLERANCE``) the DOE's diffraction over the gap is modelled: no refusal; the paper's
    f/1.8 lens (27.5 mm pupil) holds the baffle by far."""
    cam = doefab.Camera(**COARSE)
    _plan(cam)
    _plan(cam.replace(lens_f_number=cam.focal_length / (8.64e-3 * 0.995)))  # pupil 0.5 % narrower
    with pytest.raises(doefab.DoefabError, match="entrance pupil"):
        _plan(cam.replace(lens_f_number=cam.focal_length / (8.64e-3 * 0.985)))  # 1.5 % narrower
