"""``doefab doctor``'s "the system" table for a camera that is not the prototype, against hand-computed optics
(thin lens, Airy radius, first-order grating spots, N-BK7's index from SCHOTT's Sellmeier coefficients)."""

import math
import re
from pathlib import Path

import pytest

from doefab.pipeline.doctor import explain
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

REPO = Path(__file__).resolve().parents[2]


def _nbk7(lam_um: float) -> float:  # SCHOTT N-BK7 data sheet: B1..B3, C1..C3 (µm²)
    b = (1.03961212, 0.231792344, 1.01046945)
    c = (0.00600069867, 0.0200179144, 103.560653)
    x = lam_um ** 2
    return math.sqrt(1 + sum(bi * x / (x - ci) for bi, ci in zip(b, c)))


def test_my_camera_scene_is_explained_by_hand_computed_optics():
    res = resolve(load_scene(REPO / "scenes" / "my_camera.toml"))
    rows = {r["quantity"]: r["value"] for r in explain(res)}
    f, z, n_f = 35e-3, 5.0, 4.0
    s = 1 / (1 / f - 1 / z)  # thin lens focused at 5 m
    d = f / n_f
    assert rows["f-number (DOE aperture)"] == pytest.approx(4.0, rel=1e-9)
    assert rows["DOE pixels across the aperture"] == 2188  # 8.75 mm / 4 µm, even
    assert rows["diffraction limit (Airy radius)"] == pytest.approx(1.22 * 550e-9 * s / d / 3.76e-6, rel=1e-6)
    spread = (650e-9 - 450e-9) * s / 96e-6 / 3.76e-6  # first orders s·λ/Λ at the band's ends
    assert rows["grating dispersion across the band"] == pytest.approx(spread, rel=1e-3)
    n = _nbk7(0.55)
    assert rows["substrate index"] == pytest.approx(n, abs=2e-5)
    assert rows["etch depth of 2π"] == pytest.approx(550 / (n - 1), rel=1e-4)
    assert res.settings["n_levels"] == 8 and len(res.settings["wavelengths_m"]) == 21
    # the near limit: the point whose image, behind the sensor, blurs a cone of the aperture to two pixels on it
    near = rows["depth of field's near limit (2 px blur)"]
    v = 1 / (1 / f - 1 / near)  # the near point's image distance
    assert d * (v - s) / v == pytest.approx(2 * 3.76e-6, rel=1e-6)
    far = next(r for r in explain(res) if r["quantity"].startswith("depth of field"))["meaning"]
    v_far = 1 / (1 / f - 1 / float(far.split("far limit ")[1].split(" m")[0]))  # in front of the sensor
    assert d * (s - v_far) / v_far == pytest.approx(2 * 3.76e-6, rel=0.01)  # far printed to 3 digits, ×3 here


def test_bands_outside_the_substrates_published_dispersion_are_named(tmp_path):
    """PMMA's dispersion (Sultanova et al. 2009) was fitted on 436.8–1052 nm: the scene's 450–650 nm bands lie
    inside, but a 420 nm band does not and must be named; N-BK7 (fitted 0.3–2.5 µm) covers both."""
    text = (REPO / "scenes" / "my_camera.toml").read_text()
    assert 'material = "N-BK7"' in text
    inside = resolve(load_scene(REPO / "scenes" / "my_camera.toml"))
    assert inside.warnings == ()
    pmma = tmp_path / "pmma.toml"
    pmma.write_text(text.replace('material = "N-BK7"', 'material = "PMMA"'))
    assert resolve(load_scene(pmma)).warnings == ()
    import re

    low = tmp_path / "pmma_low.toml"
    low.write_text(re.sub(r"wavelengths_nm = \[[^\]]*\]", "wavelengths_nm = [420, 500, 600]",
                          text.replace('material = "N-BK7"', 'material = "PMMA"')))
    notes = [n for n in resolve(load_scene(low)).warnings if "published dispersion" in n]  # (and the bands' spacing)
    assert len(notes) == 1 and "420 nm" in notes[0] and "500 nm" not in notes[0] and "PMMA" in notes[0]


def test_a_band_on_the_edge_of_the_published_range_is_inside_and_each_wavelength_named_once():
    """436.8 nm is PMMA's published lower limit (0.4368 µm): inside, although 436.8e-9 * 1e6 < 0.4368 in floats;
    a band listed twice is named once."""
    from doefab.optics.materials import PMMA, fit_range_warning

    assert fit_range_warning(PMMA, [436.8e-9, 1052e-9]) is None
    note = fit_range_warning(PMMA, [420e-9, 420e-9, 500e-9])
    assert note.count("420 nm") == 1 and "500 nm" not in note


@pytest.mark.parametrize("levels, masks", [(2, "1 binary mask"), (8, "3 binary masks")])
def test_the_mask_count_is_said_in_words_that_agree(tmp_path, levels, masks):
    text = (REPO / "scenes" / "my_camera.toml").read_text()
    assert "n_levels = 8" in text
    p = tmp_path / "s.toml"
    p.write_text(text.replace("n_levels = 8", f"n_levels = {levels}"))
    meaning = next(r["meaning"] for r in explain(resolve(load_scene(p))) if r["quantity"] == "etch depth of 2π")
    assert f"{levels} levels of " in meaning and meaning.endswith(f" nm on {masks}")


@pytest.mark.parametrize("value,accepted", [("inf", True), ('"inf"', True), ("-inf", False), ("nan", False),
                                            ("2e6", False)])
def test_a_camera_focused_at_infinity(tmp_path, value, accepted):
    """``focus_distance_m = inf`` puts the sensor one focal length behind the lens; the near limit is then the
    hyperfocal distance D·f / (2 px) and the far limit infinity. Other non-finite or too-far values are refused."""
    from doefab.errors import DoefabError

    path = tmp_path / "inf.toml"
    path.write_text(f'task = "hdr"\nstages = ["design"]\n[camera]\nfocal_length_mm = 35.0\nf_number = 4.0\n'
                    f'lens_f_number = 2.0\nfocus_distance_m = {value}\nsensor_pitch_um = 3.76\n')
    if not accepted:
        with pytest.raises(DoefabError, match="camera.focus_distance_m"):
            resolve(load_scene(path))
        return
    res = resolve(load_scene(path))
    assert math.isinf(res.camera.focus_distance) and res.camera.sensor_distance == pytest.approx(35e-3, rel=1e-12)
    row = next(r for r in explain(res) if r["quantity"].startswith("depth of field"))
    assert row["value"] == pytest.approx(35e-3 / 4.0 * 35e-3 / (2 * 3.76e-6), rel=1e-9)
    assert "far limit ∞" in row["meaning"] and "infinity" in row["meaning"] and "inf m" not in row["meaning"]
    from doefab.pipeline.doctor import diagnose

    checks = [r["check"] for r in diagnose(load_scene(path), precision_check=False)]
    assert any("steepest plane's wavefront (infinity)" in c for c in checks), checks
    assert not any("inf m" in c for c in checks), checks


def _silica(lam_um: float) -> float:  # Malitson 1965, fused silica: B1..B3, C1..C3 (µm)
    b, c = (0.6961663, 0.4079426, 0.8974794), (0.0684043, 0.1162414, 9.896161)
    x = lam_um ** 2
    return math.sqrt(1 + sum(bi * x / (x - ci ** 2) for bi, ci in zip(b, c)))


@pytest.mark.parametrize("stages,diagonal,angle", [
    ('["design"]', 43.3, None),  # a full-frame sensor 50.5 mm behind the lens: atan(21.65 / 50.505)
    ('["design", "holder"]', None, 24.0),  # the holder's default field
    ('["design"]', None, False),  # no field known: no row
    ('["design", "holder"]', None, 30.0)])  # as given, at a 1 µm design wavelength
def test_the_etch_steps_phase_at_the_fields_edge_is_snells(tmp_path, stages, diagonal, angle):
    """A plane wave at θ crosses a step h of glass with the phase k·h·(n·cos θt − cos θ), n·sin θt = sin θ,
    against k·h·(n − 1) on axis (fused silica at the design wavelength: 550 nm, or 1000 nm where the field is
    given as 30°)."""
    wide = angle == 30.0
    path = tmp_path / "field.toml"
    path.write_text(f'task = "hdr"\nstages = {stages}\n[camera]\nfocal_length_mm = 50.0\nf_number = 5.6\n'
                    f'lens_f_number = 1.8\nfocus_distance_m = 5.0\n'
                    + (f"sensor_diagonal_mm = {diagonal}\n" if diagonal else "")
                    + ("[holder]\nfield_half_angle_deg = 30.0\n[fabrication]\ndesign_wavelength_nm = 1000\n"
                       if wide else ""))
    scene = load_scene(path)
    rows = {r["quantity"]: r for r in explain(resolve(scene), scene)}
    if angle is False:
        assert "etch step's phase at the field's edge" not in rows
        return
    s = 1 / (1 / 50e-3 - 1 / 5.0)
    th = math.atan(diagonal * 1e-3 / 2 / s) if angle is None else math.radians(angle)
    n = _silica(1.0 if wide else 0.55)
    t = math.asin(math.sin(th) / n)
    expect = ((n * math.cos(t) - math.cos(th)) / (n - 1) - 1) * 100
    assert rows["etch step's phase at the field's edge"]["value"] == pytest.approx(expect, rel=1e-6 if wide else 1e-3)
    assert 9 < expect < 11 if wide else 5 < expect < 7  # the prototype's field: about 6 % deeper at the corners


@pytest.mark.parametrize("plane,accepted", [("inf", True), ('"inf"', True), ("-inf", False)])
def test_a_plane_at_infinity_is_written_either_way(tmp_path, plane, accepted):
    """``optics.depths_m`` takes a plane at infinity as TOML's inf or as the word "inf", as the focus does."""
    from doefab.errors import DoefabError

    path = tmp_path / "plane.toml"
    path.write_text(f'task = "hdr"\nstages = ["design"]\n[camera]\nfocus_distance_m = inf\n[optics]\n'
                    f'depths_m = [{plane}]\n')
    if accepted:
        assert resolve(load_scene(path)).settings["depths_m"] == ["inf"]
    else:
        with pytest.raises(DoefabError, match="optics.depths_m"):
            resolve(load_scene(path))


def test_a_macro_lens_depth_of_field_is_told_with_the_digits_that_tell_its_limits_apart(tmp_path):
    """A 100 mm f/2.8 macro lens at 0.3 m on 4.3 µm pixels: the depth of field (2 px blur) is
    z_f ± ≈ 2p·z_f² / (D·s) ≈ 0.14 mm, so 3 digits would print both limits as 0.3 m; the far limit is printed with
    the digits that tell it from the near one."""
    p = tmp_path / "macro.toml"
    p.write_text('task = "depth"\nstages = ["design"]\n[camera]\nfocal_length_mm = 100\nf_number = 2.8\n'
                 'lens_f_number = 2.8\nfocus_distance_m = 0.3\nsensor_pitch_um = 4.3\ndoe_pitch_um = 20\n'
                 '[optics]\ndepths_m = [0.299, 0.3, 0.301]\nkernel_px = 255\n')
    res = resolve(load_scene(p))
    row = next(r for r in explain(res) if r["quantity"].startswith("depth of field"))
    s = 1 / (1 / 0.1 - 1 / 0.3)
    d = 0.1 / 2.8
    far = 1 / (1 / 0.3 - 2 * 4.3e-6 / (d * s))
    assert row["value"] == pytest.approx(1 / (1 / 0.3 + 2 * 4.3e-6 / (d * s)), rel=1e-9)
    shown = float(re.search(r"far limit ([\d.]+) m", row["meaning"])[1])
    assert shown == pytest.approx(far, abs=5e-6) and shown != pytest.approx(0.3, abs=5e-6)


def test_a_scenes_holder_thread_no_filter_has_is_warned_with_its_key(tmp_path):
    text = (REPO / "scenes" / "hdr.toml").read_text()
    assert "thread_diameter_mm = 49.0" in text and resolve(load_scene(REPO / "scenes" / "hdr.toml")).warnings == ()
    odd = tmp_path / "odd.toml"
    odd.write_text(text.replace("thread_diameter_mm = 49.0", "thread_diameter_mm = 49.3"))
    notes = resolve(load_scene(odd)).warnings
    assert len(notes) == 1 and notes[0].startswith("holder.thread_diameter_mm 49.3 is no common filter thread")
    assert "nearest 49 and 52 mm" in notes[0]
    off = tmp_path / "no_holder.toml"  # no holder is built: nothing to warn of
    off.write_text(odd.read_text().replace('"holder", ', ""))
    assert resolve(load_scene(off)).warnings == ()


def test_a_calibration_its_noise_swamps_is_warned_with_the_scenes_sensor_noise(tmp_path):
    """A budget whose crosstalk calibration (16 rows at 5 % of full scale) scatters the smallest ratio (r→l at the
    calibrated region's right edge: 5 % − the 2 % slope) by 4.5 % of it with the default sensor (3 e⁻ read noise)
    passes silently; the same calibration on the scene's sensor of 40 e⁻ read noise scatters it by 26 %
    (√(0.03·0.97·1250 + 40²·0.9418) / (1250·√16) / 0.03), over the 5 % warned of, as the tolerance stage draws it;
    without the tolerance stage there is nothing to warn of."""
    from doefab.imaging.sensor import Sensor
    from doefab.pipeline.systemnotes import calibration_notes
    from doefab.tolerance.errors import calibration_warning, load_budget

    (tmp_path / "dim.toml").write_text("[sensor]\ncalibration_rows = 16\ncalibration_level = 0.05\n")
    text = (REPO / "scenes" / "hdr.toml").read_text().replace('budget = "default"', 'budget = "dim.toml"')
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    assert resolve(load_scene(scene)).warnings == ()
    scene.write_text(text + "\n[sensor]\nread_noise_e = 40.0\n")
    notes = [n for n in resolve(load_scene(scene)).warnings if "crosstalk calibration" in n]  # (and the networks')
    assert len(notes) == 1 and "calibration of 16 rows at calibration_level = 0.05" in notes[0], notes
    assert "40 e⁻ read noise" in notes[0] and "r→l ratio at the calibrated region's right edge (3 %)" in notes[0]
    assert "±0.79 percentage points (26 % of it)" in notes[0]
    assert calibration_warning(load_budget(tmp_path / "dim.toml")) is None  # the budget's own (default) noise
    scene.write_text(text.replace('"tolerance", ', "") + "\n[sensor]\nread_noise_e = 40.0\n")
    assert calibration_notes(load_scene(scene), Sensor(read_noise_e=40.0)) == []
