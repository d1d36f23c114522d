"""A scene's structure, keys of another task, choice values and design keys that only the committed design
settles: each refused (or warned of) with the key and its fix before any folder is made, never as a Python
error; paths a scene names are relative to the scene file wherever the command runs."""

import pytest

from doefab.errors import DoefabError
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve


def _scene(tmp_path, text: str, task: str | None = "hdr"):
    p = tmp_path / "scene.toml"
    p.write_text((f'task = "{task}"\n' if task else "") + f"{text}\n")
    return p


def _refused(path) -> str:
    with pytest.raises(DoefabError) as exc:
        resolve(load_scene(path))
    return str(exc.value)


@pytest.mark.parametrize("text, needle", [
    ("[[holder]]\nwall_mm = 2.0", "[[holder]] is an array of tables: write [holder] once"),
    ("holder = 5", "holder = 5: [holder] is a table"),
    ("reconstruction = 5", "[reconstruction] is a table"),
    ("tolerance = \"default\"", "[tolerance] is a table"),
    ('[camera]\nfocal_length_mm = "35.0 mm"', "write focal_length_mm = 35.0 without quotes (the unit, mm"),
    ('[camera]\nfocal_length_mm = "3.5 cm"', "write the number in mm, without quotes"),
    ("[optics]\nkernel_px = 191.0", "must be a whole number, got 191.0: write 191"),
    ('[optics]\nkernel_px = "191"', "must be a whole number, got '191': write kernel_px = 191 without quotes"),
    ("[fabrication]\nn_levels = 8.0", "write n_levels = 8"),
    ('[fabrication]\npattern_faces = "LENS"', 'write pattern_faces = "lens"'),
    ("[fabrication]\noasis = 1", "must be true or false"),
])
def test_a_section_or_value_of_the_wrong_shape_names_the_line_to_write(tmp_path, text, needle):
    """``holder = 5`` or ``[[holder]]`` was an internal TypeError (exit 1, "please report it"); a number in quotes
    or with its unit, a float for an integer choice and another case are named with the line to write."""
    msg = _refused(_scene(tmp_path, text))
    assert needle in msg, msg


@pytest.mark.parametrize("task, needle", [
    ('["hdr"]', "task ['hdr'] is not one of"), ('"HDR"', 'write task = "hdr"'), ('" depth "', 'write task = "depth"')])
def test_a_task_of_another_type_or_case_names_the_choice(tmp_path, task, needle):
    msg = _refused(_scene(tmp_path, f"task = {task}", task=None))
    assert needle in msg, msg


def test_a_missing_task_says_to_add_one(tmp_path):
    msg = _refused(_scene(tmp_path, "[camera]\nfocal_length_mm = 35.0", task=None))
    assert "task is missing: add task = " in msg, msg


@pytest.mark.parametrize("task, key, value", [("hyperspectral", "ring_width_px", 1.0), ("depth", "streak_arm_px", 30),
                                              ("hdr", "grating_period_um", 90.0), ("hdr", "ring_law", '"defocus"')])
def test_a_key_of_another_task_is_refused_with_the_tasks_that_take_it(tmp_path, task, key, value):
    """It was GratingTask.__init__()'s "unexpected keyword argument 'delta_px'"."""
    msg = _refused(_scene(tmp_path, f"[design]\n{key} = {value}", task=task))
    assert f"design.{key} applies to task = " in msg and f"(this scene's task is '{task}'): delete it" in msg, msg
    assert "__init__" not in msg


def test_knots_on_a_pixel_design_are_refused_before_the_design_stage(tmp_path):
    """``design.knots`` passed every check and stopped the design stage with a flag of ``doefab design``."""
    msg = _refused(_scene(tmp_path, "[design]\nknots = 500"))
    assert "design.knots = 500: knots shape a radial profile only" in msg and "(the committed design's)" in msg, msg
    one = _refused(_scene(tmp_path, "[design]\nknots = 1", task="depth"))
    assert "design.knots: 1 knot makes no profile" in one, one
    res = resolve(load_scene(_scene(tmp_path, "[design]\nknots = 40", task="depth")))  # the committed one is radial
    assert res.settings["knots"] == 40


def test_a_radial_profile_for_a_target_it_cannot_form_is_warned_of(tmp_path):
    res = resolve(load_scene(_scene(tmp_path, '[design]\nparameterization = "radial"')))
    assert any("cannot form the streak target" in w for w in res.warnings), res.warnings
    depth = resolve(load_scene(_scene(tmp_path, '[design]\nparameterization = "radial"', task="depth")))
    assert not any("cannot form" in w for w in depth.warnings), depth.warnings


def test_a_grating_period_as_wide_as_the_coded_half_is_refused(tmp_path):
    """No first order separates from the zeroth where not one period fits across the coded half (8.64 mm / 2)."""
    msg = _refused(_scene(tmp_path, "[design]\ngrating_period_um = 6000.0", task="hyperspectral"))  # D/2 < 6 mm < D
    assert "the grating period 6000 µm (design.grating_period_um) is not shorter than the coded half (4320 µm across)" in msg
    assert "set design.grating_period_um shorter, e.g. 86.4" in msg, msg


def test_bands_closer_than_a_pixel_apart_are_warned_of(tmp_path):
    """A period that lands several bands on one sensor pixel (here 5× the committed one) makes a spectral camera
    that cannot tell them apart: a warning with the key that spreads them."""
    res = resolve(load_scene(_scene(tmp_path, "[design]\ngrating_period_um = 432.0", task="hyperspectral")))
    assert any("bands per sensor pixel" in w for w in res.warnings), res.warnings
    shipped = resolve(load_scene(_scene(tmp_path, "", task="hyperspectral")))
    assert not any("bands per sensor pixel" in w for w in shipped.warnings), shipped.warnings


def test_a_design_wavelength_far_above_the_bands_is_warned_of(tmp_path):
    res = resolve(load_scene(_scene(tmp_path, "[fabrication]\ndesign_wavelength_nm = 2000")))
    assert any("is long for the bands" in w for w in res.warnings), res.warnings
    assert not any("is long for the bands" in w for w in resolve(load_scene(_scene(tmp_path, ""))).warnings)


def test_the_depth_ring_follows_the_blur_only_where_the_blur_changes(tmp_path):
    """Another substrate, design wavelength or lens f-number leave the plain half's blur, so the ring keeps the
    paper's law (it moved from 20 to 28 px); another aperture, focus, pixel pitch or sensor distance takes the
    blur's ring."""
    shipped = resolve(load_scene(_scene(tmp_path, "", task="depth"))).task.ring_max_px
    for text in ('[fabrication]\nmaterial = "N-BK7"', "[fabrication]\ndesign_wavelength_nm = 600",
                 "[camera]\nlens_f_number = 1.4"):
        assert resolve(load_scene(_scene(tmp_path, text, task="depth"))).task.ring_max_px == shipped, text
    for text in ("aperture_diameter_mm = 8.7", "focus_distance_m = 3.0", "sensor_pitch_um = 6.0",
                 "sensor_distance_mm = 49.5"):  # each of D, z_focus, pitch, s in D·s·|1/z_focus − 1/z| / pitch
        other = resolve(load_scene(_scene(tmp_path, "[camera]\n" + text, task="depth")))
        assert other.task.ring_max_px != shipped, text


def test_a_budget_path_is_relative_to_the_scene_wherever_the_command_runs(tmp_path, monkeypatch):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "b.toml").write_text("[etch]\nsystematic_sigma_percent = 2.0\n")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    text = '[tolerance]\nbudget = "elsewhere/b.toml"'
    monkeypatch.chdir(tmp_path)  # the path exists from here, not from the scene's folder
    with pytest.raises(DoefabError, match="no file at .*scenes/elsewhere/b.toml"):
        load_scene(_scene(scenes, text))
    assert load_scene(_scene(scenes, '[tolerance]\nbudget = "../elsewhere/b.toml"')).budget_path().resolve() == (
        tmp_path / "elsewhere" / "b.toml")


@pytest.mark.parametrize("fields, needle", [
    ({"camera": {"focal_lenght_mm": 35.0}}, "unknown key camera.focal_lenght_mm"),
    ({"camera": {"focal_length_mm": "35"}}, "camera.focal_length_mm must be a number"),
    ({"stages": ("bogus",)}, "stages holds 'bogus'"),
    ({"tolerance": {"samples": -5}}, "tolerance.samples = -5 is outside"),
])
def test_a_scene_built_in_code_is_checked_as_a_file_is(tmp_path, fields, needle):
    """``resolve`` (and so ``prepare_scene`` and ``run_scene``) took a hand-built Scene unchecked: a typo was
    ignored, a string focal length was a TypeError."""
    from pathlib import Path

    from doefab.pipeline.scene import STAGES, Scene

    scene = Scene(**{"path": Path(tmp_path / "code.toml"), "task": "hdr", "stages": STAGES, **fields})
    with pytest.raises(DoefabError) as exc:
        resolve(scene)
    assert needle in str(exc.value), str(exc.value)


def test_a_quick_runs_note_names_the_cuts_of_the_stages_that_ran():
    from doefab.pipeline.stages import quick_note

    every = quick_note()
    assert "a new design" in every and "networks trained here" in every and "Monte Carlo parts" in every
    assert "no STEP file" in every and "no KLayout mask check" in every
    design_only = quick_note({"design": {"status": "ran"}, "tolerance": {"status": "skipped"},
                              "reconstruction": {"status": "skipped", "weights": "train"}})
    assert "a new design" in design_only
    for cut in ("networks trained", "Monte Carlo", "scenes of", "STEP", "KLayout"):
        assert cut not in design_only, (cut, design_only)
    shipped = quick_note({"design": {"status": "reused"}, "reconstruction": {"status": "reused", "weights": "shipped"},
                          "masks": {"status": "reused"}})
    assert "a new design" not in shipped and "networks trained" not in shipped
    assert "the reconstruction table on" in shipped and "each judged part" not in shipped and "KLayout" in shipped
