"""A scene whose lens's entrance pupil is narrower than the DOE's baffle is refused (``sampling.stop_checks``): the
PSFs carry the whole baffle's light, split at the DOE, and such a lens would block the baffle's outer ring. The
numbers are the thin lens's by hand: a 35 mm lens focused at 5 m, its pupil focal length / lens f-number across."""

import re

import pytest

from doefab.errors import DoefabError
from doefab.pipeline.doctor import diagnose
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

CAM = {"focal_length_mm": 35.0, "focus_distance_m": 5.0, "sensor_pitch_um": 3.76, "doe_pitch_um": 4.0}


def _scene(tmp_path, name="s.toml", **camera):
    text = 'task = "hdr"\nstages = ["design"]\n[camera]\n' + "".join(
        f"{k} = {v}\n" for k, v in {**CAM, **camera}.items())
    path = tmp_path / name
    path.write_text(text)
    return load_scene(path)


def _refusal(scene) -> str:
    with pytest.raises(DoefabError) as err:
        resolve(scene)
    msg = str(err.value)
    with pytest.raises(DoefabError) as doc:  # doctor refuses what run refuses
        diagnose(scene, precision_check=False)
    assert "entrance pupil is narrower" in str(doc.value)
    return msg


def test_a_lens_pupil_narrower_than_the_baffle_is_refused_and_the_fix_passes(tmp_path):
    msg = _refusal(_scene(tmp_path, f_number=4.0, lens_f_number=5.6))
    # pupil 35 mm / 5.6 = 6.25 mm, baffle 35 mm / 4 = 8.75 mm
    assert "6.25 mm entrance pupil" in msg and "8.75 mm baffle" in msg, msg
    value = float(re.search(r"camera\.f_number ≥ ([\d.]+)", msg).group(1))
    assert value == pytest.approx(5.6)
    assert resolve(_scene(tmp_path, "fixed.toml", f_number=value, lens_f_number=5.6)).camera.doe_is_stop


def test_a_scene_that_sets_the_aperture_is_told_the_aperture(tmp_path):
    msg = _refusal(_scene(tmp_path, aperture_diameter_mm=9.0, lens_f_number=5.0))
    assert "camera.f_number" not in msg
    value = float(re.search(r"camera\.aperture_diameter_mm ≤ ([\d.]+)", msg).group(1))
    assert value == pytest.approx(35 / 5.0)  # the pupil
    resolve(_scene(tmp_path, "fixed.toml", aperture_diameter_mm=value, lens_f_number=5.0))


@pytest.mark.parametrize("narrower,refused", [(0.009, False), (0.011, True), (-0.5, False)])
def test_a_pupil_about_as_wide_as_the_baffle_is_accepted(tmp_path, narrower, refused):
    """Within 1 % either may be the stop (the model propagates the DOE's diffraction over the gap to the lens);
    a pupil 1.1 % narrower cuts the DOE; a wider one leaves the baffle the stop."""
    scene = _scene(tmp_path, aperture_diameter_mm=8.0, lens_f_number=35 / (8.0 * (1 - narrower)))
    if refused:
        assert "8.00 mm baffle" in _refusal(scene)
    else:
        resolve(scene)


@pytest.mark.parametrize("lens,told", [(35 / 6.3, 5.56), (4.98, 4.98)])
def test_the_suggested_f_number_is_rounded_up_to_one_that_passes(tmp_path, lens, told):
    """A lens of f/5.5556 (35 mm / 6.3 mm) is told f/5.56, not the f/5.55 that would still be refused; a lens of
    f/4.98 is told f/4.98 (4.98 / 0.01 is 498.00000000000006 in floating point, not a reason for 4.99)."""
    msg = _refusal(_scene(tmp_path, f_number=4.0, lens_f_number=lens))
    value = float(re.search(r"camera\.f_number ≥ ([\d.]+)", msg).group(1))
    assert value == told
    assert resolve(_scene(tmp_path, "fixed.toml", f_number=value, lens_f_number=lens)).camera.doe_is_stop


def test_the_window_blur_check_suggests_no_focus_whose_lens_would_cut_the_doe(tmp_path):
    """The sensor distance fixed at 50 mm, a nearer focus shortens the focal length and so the lens's pupil: at
    100 m a 12.5 mm baffle behind an f/4 lens is within 1 % of its 12.49 mm pupil; at the planes' harmonic middle
    (0.667 m) the pupil is 11.6 mm. The focus that would hold the blur is not suggested."""
    path = tmp_path / "near.toml"
    path.write_text('task = "depth"\nstages = ["design"]\n[camera]\nsensor_distance_mm = 50.0\n'
                    'aperture_diameter_mm = 12.5\nlens_f_number = 4.0\nfocus_distance_m = 100.0\n'
                    'doe_pitch_um = 10.0\n[optics]\ndepths_m = [0.5, 0.75, 1.0]\n')
    with pytest.raises(DoefabError) as err:
        resolve(load_scene(path))
    msg = str(err.value)
    assert "half disc" in msg and "entrance pupil is narrower" not in msg, msg
    assert "camera.focus_distance_m" not in msg, msg
    # the focus the blur alone would take does cut the DOE: the stop check refuses it
    with pytest.raises(DoefabError, match="entrance pupil is narrower"):
        resolve(load_scene(_with_focus(path, 0.667)))


def _with_focus(path, focus: float):
    out = path.with_name("focused.toml")
    out.write_text(path.read_text().replace("focus_distance_m = 100.0", f"focus_distance_m = {focus}"))
    return out


def test_a_pupil_narrower_than_the_aperture_keys_range_is_told_an_f_number(tmp_path):
    """A 4 mm lens at f/64 has a 0.0625 mm pupil, below the 0.1 mm where camera.aperture_diameter_mm's range ends:
    a scene that sets the aperture is told the f-number in its place (which reaches it, 4 mm / 64), and that scene
    passes the stop check; at f/32 (0.125 mm) it is told the aperture."""
    cam = {"focal_length_mm": 4.0, "doe_pitch_um": 4.0, "sensor_pitch_um": 1.0, "focus_distance_m": 1.0}
    msg = _refusal(_scene(tmp_path, **cam, aperture_diameter_mm=0.5, lens_f_number=64.0))
    assert "0.06 mm entrance pupil" in msg, msg
    assert "aperture_diameter_mm ≤" not in msg and "camera.f_number ≥ 64 (in place of" in msg, msg
    for fixed in ({"f_number": 64.0, "lens_f_number": 64.0}, {"aperture_diameter_mm": 0.125, "lens_f_number": 32.0}):
        try:
            resolve(_scene(tmp_path, "fixed.toml", **cam, **fixed))
        except DoefabError as exc:  # so small an aperture may fail other checks, not the stop's
            assert "entrance pupil is narrower" not in str(exc), str(exc)
    msg = _refusal(_scene(tmp_path, **cam, aperture_diameter_mm=0.5, lens_f_number=32.0))
    value = float(re.search(r"camera\.aperture_diameter_mm ≤ ([\d.]+)", msg).group(1))
    assert value == pytest.approx(0.125)
