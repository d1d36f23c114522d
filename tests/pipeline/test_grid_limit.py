"""A DOE grid above ``MAX_DOE_PIXELS`` across is refused with the pitch and the aperture that bring it within the
limit, each in the scene's own key and rounded to the side that fits (by hand: a 200 mm lens at f/2.8 has a
71.43 mm DOE aperture, 17 858 pixels of 4 µm)."""

import re

import pytest

from doefab.errors import DoefabError
from doefab.pipeline.sampling import MAX_DOE_PIXELS, MIN_DOE_PIXELS, quick_sampling
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

CAM = {"focal_length_mm": 200.0, "focus_distance_m": 5.0, "sensor_pitch_um": 3.76, "doe_pitch_um": 4.0}


def _problems(tmp_path, **camera) -> str:
    path = tmp_path / "s.toml"
    path.write_text('task = "hdr"\nstages = ["design"]\n[camera]\n'
                    + "".join(f"{k} = {v}\n" for k, v in {**CAM, **camera}.items()))
    try:
        resolve(load_scene(path))
    except DoefabError as exc:
        return str(exc)
    return ""


def _fix(msg: str, key: str) -> float:
    return float(re.search(rf"camera\.{key} [≥≤] ([\d.]+)", msg).group(1))


@pytest.mark.parametrize("aperture_key", ["f_number", "aperture_diameter_mm"])
def test_a_grid_above_the_limit_names_fixes_that_fit(tmp_path, aperture_key):
    wide = {"f_number": 2.8} if aperture_key == "f_number" else {"aperture_diameter_mm": 200 / 2.8}
    msg = _problems(tmp_path, **wide)
    assert "the DOE grid would be 17858² pixels" in msg, msg
    pitch_um = _fix(msg, "doe_pitch_um")
    assert pitch_um == pytest.approx(8.72)  # 71.43 mm / 8192 = 8.7193 µm, rounded up
    assert "the DOE grid" not in _problems(tmp_path, **wide, **{"doe_pitch_um": pitch_um})
    smaller = _fix(msg, aperture_key)
    # f/6.11: 200 mm / (8192 × 4 µm) = f/6.1035 rounded up; 8192 × 4 µm = 32.768 mm rounded down
    assert smaller == pytest.approx(6.11 if aperture_key == "f_number" else 32.7)
    assert "the DOE grid" not in _problems(tmp_path, **{aperture_key: smaller})
    other = "aperture_diameter_mm" if aperture_key == "f_number" else "f_number"
    assert f"camera.{other}" not in msg  # the fix is in the key the scene sets
    assert MAX_DOE_PIXELS * pitch_um * 1e-3 >= 200 / 2.8


@pytest.mark.parametrize("aperture_key", ["f_number", "aperture_diameter_mm"])
def test_a_grid_below_the_floor_is_one_problem_naming_fixes_that_fit(tmp_path, aperture_key):
    """A 200 mm lens at f/64 has a 3.125 mm DOE aperture: 7.8 pixels of 400 µm, rounded up to an even 8. Refused
    in the scene's words (not a Camera's internal limit), with fixes that reach ``MIN_DOE_PIXELS``: 3.125 mm / 16
    = 195.3 µm rounded down, f/31.25 (200 mm / (16 × 400 µm)) rounded down and 6.4 mm."""
    narrow = {"f_number": 64.0} if aperture_key == "f_number" else {"aperture_diameter_mm": 3.125}
    msg = _problems(tmp_path, **narrow, doe_pitch_um=400.0)
    assert "1 problem: the DOE grid would be 8 pixels across" in msg and "Camera." not in msg, msg
    pitch_um = _fix(msg, "doe_pitch_um")
    assert pitch_um == pytest.approx(195)
    assert "the DOE grid" not in _problems(tmp_path, **narrow, doe_pitch_um=pitch_um)
    larger = _fix(msg, aperture_key)
    assert larger == pytest.approx(31.2 if aperture_key == "f_number" else 6.4)
    assert "the DOE grid" not in _problems(tmp_path, **{aperture_key: larger}, doe_pitch_um=400.0)
    assert MIN_DOE_PIXELS * pitch_um * 1e-3 <= 3.125


def test_the_quick_grid_keeps_at_least_the_floor():
    """``--quick`` coarsens a grid by the factor nearest 4 that divides it, never below ``MIN_DOE_PIXELS``."""
    assert quick_sampling(3200, 1) == 4
    assert quick_sampling(48, 1) == 3  # 48 / 4 = 12 < 16: the factor 3 leaves 16
    assert quick_sampling(16, 1) == 1


def test_an_explicit_sampling_that_leaves_a_design_grid_below_the_floor_names_the_factors_that_do_not(tmp_path):
    """A 16 mm lens at f/10 on 40 µm DOE pixels: 1.6 mm / 40 µm = 40 pixels; design.sampling 4 leaves 10 (refused,
    naming 1 and 2, which leave 40 and 20), 2 passes this check."""
    p = tmp_path / "s.toml"
    text = ('task = "hdr"\nstages = ["design"]\n[camera]\nfocal_length_mm = 16.0\nf_number = 10.0\n'
            'lens_f_number = 2.8\nsensor_pitch_um = 3.45\ndoe_pitch_um = 40.0\n[design]\nsampling = {}\n')
    p.write_text(text.format(4))
    with pytest.raises(DoefabError, match=r"design.sampling 4 leaves a design grid of 10 px, below the 16 a pattern "
                                          r"needs: use 1 or 2"):
        resolve(load_scene(p))
    p.write_text(text.format(2))
    try:
        resolve(load_scene(p))
    except DoefabError as exc:
        assert "leaves a design grid" not in str(exc)
