"""``doefab doctor``'s spectral-sampling row says, where the grating spreads the bands over fewer pixels than
there are bands, the period that spreads them one per pixel (``tasks.grating.period_for_spread``). By hand: a
phone camera (4.38 mm lens focused at 1 m, 1.4 µm pixels) keeps the template's 96 µm period, which it spreads
400–700 nm over s·(sin θ700 − sin θ400) / p ≈ 9.8 px (where the Fraunhofer model puts the first orders; a
rectilinear lens's s·tan θ differs by 0.0002 px): 31 bands, 3.1 per pixel."""

import math
import re
from pathlib import Path

import pytest

import doefab
from doefab.pipeline.doctor import explain
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve
from doefab.tasks.grating import period_for_spread

PHONE = {"focal_length_mm": 4.38, "f_number": 1.73, "lens_f_number": 1.73, "focus_distance_m": 1.0,
         "sensor_pitch_um": 1.4, "doe_pitch_um": 4.0}


def _spread_px(s: float, p: float, period: float, lo: float = 400e-9, hi: float = 700e-9) -> float:
    """First orders' distance by the grating equation sin θ = λ / Λ, written out here: the model puts an order at
    s·sin θ on the sensor."""
    return s * (hi - lo) / period / p


@pytest.mark.parametrize("spread", [5.0, 30.0, 120.0])
def test_the_period_spreads_the_band_over_the_pixels_asked(spread):
    cam = doefab.Camera(sensor_distance=4.4e-3, sensor_pitch=1.4e-6)
    period = period_for_spread(cam, 400e-9, 700e-9, spread)
    assert _spread_px(4.4e-3, 1.4e-6, period) == pytest.approx(spread, rel=1e-9)
    assert period == pytest.approx(4.4e-3 * 300e-9 / 1.4e-6 / spread, rel=1e-9)  # Λ = s Δλ / (p · spread)


def _scene(tmp_path, name="s.toml", design=""):
    path = tmp_path / name
    path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\n'
                    + "".join(f"{k} = {v}\n" for k, v in PHONE.items()) + f"[design]\n{design}")
    return load_scene(path)


def _sampling(res) -> tuple[float, str]:
    row = next(r for r in explain(res) if r["quantity"] == "spectral sampling")
    return row["value"], row["meaning"]


def test_a_coarse_spread_names_the_period_that_spreads_one_band_per_pixel(tmp_path):
    res = resolve(_scene(tmp_path, design="grating_period_um = 96.0\n"))
    s = res.camera.sensor_distance
    value, meaning = _sampling(res)
    assert value == pytest.approx(300 / _spread_px(s, 1.4e-6, 96e-6), rel=1e-6)
    assert "3.1 bands per pixel" in meaning and "7.9 DOE pixels per period" in meaning, meaning  # 31.42 / 4 µm
    period_um = float(re.search(r"design\.grating_period_um = ([\d.]+)", meaning).group(1))
    kernel = int(re.search(r"optics\.kernel_px ≥ (\d+)", meaning).group(1))
    assert _spread_px(s, 1.4e-6, period_um * 1e-6) >= 30  # one band per pixel or better
    assert _spread_px(s, 1.4e-6, (period_um + 0.02) * 1e-6) < 30  # and no finer than it needs
    fixed = resolve(_fixed(tmp_path, period_um, kernel))  # refused if the window were too small
    v2, m2 = _sampling(fixed)
    assert v2 <= 10.0 and "bands per pixel" not in m2, m2


def _fixed(tmp_path, period_um: float, kernel: int):
    path = tmp_path / "fixed.toml"
    path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\n'
                    + "".join(f"{k} = {v}\n" for k, v in PHONE.items())
                    + f"[optics]\nkernel_px = {kernel}\n[design]\ngrating_period_um = {period_um}\n")
    return load_scene(path)


def test_the_shipped_hyperspectral_scenes_get_no_note():
    repo = Path(__file__).resolve().parents[2]
    for name in ("hyperspectral.toml", "my_camera.toml"):
        _, meaning = _sampling(resolve(load_scene(repo / "scenes" / name)))
        assert meaning == "bands closer than this land on the same pixel", (name, meaning)


def test_no_period_is_named_where_its_window_would_leave_the_alias_free_field(tmp_path):
    """151 bands 2 nm apart would need Λ ≈ 6.35 µm (1.6 DOE pixels of 4 µm) and a window of about 707 px, while
    the DOE sampling's alias-free field at 400 nm is λ·s / (2·pitch) / p ≈ 157 px each way: no period fits."""
    bands = ", ".join(str(400 + 2 * i) for i in range(151))
    path = tmp_path / "many.toml"
    path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\n'
                    + "".join(f"{k} = {v}\n" for k, v in PHONE.items()) + f"[optics]\nwavelengths_nm = [{bands}]\n")
    res = resolve(load_scene(path))
    _, meaning = _sampling(res)
    assert "no grating period spreads them one per pixel" in meaning and "design.grating_period_um" not in meaning
    field = 400e-9 * res.camera.sensor_distance / (2 * 4e-6) / 1.4e-6
    assert f"alias-free field at 400 nm is {2 * field - 1:.0f} px" in meaning, meaning


def test_the_note_reads_the_bands_in_any_order(tmp_path):
    """The same 31 bands listed from 700 nm down to 400 nm get the same period as listed upwards."""
    notes = []
    for name, order in (("up.toml", range(400, 701, 10)), ("down.toml", range(700, 399, -10))):
        path = tmp_path / name
        path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\n'
                        + "".join(f"{k} = {v}\n" for k, v in PHONE.items())
                        + f"[optics]\nwavelengths_nm = [{', '.join(map(str, order))}]\n"
                        + "[design]\ngrating_period_um = 96.0\n")
        notes.append(re.search(r"design\.grating_period_um = [\d.]+", _sampling(resolve(load_scene(path)))[1]))
    assert notes[0] and notes[1] and notes[0].group(0) == notes[1].group(0) == "design.grating_period_um = 31.42"


def _far_px(s: float, p: float, period: float, lam: float = 700e-9) -> float:
    return s * lam / period / p  # s·sin θ, sin θ = λ / Λ


WIDE = {"focal_length_mm": 16.0, "f_number": 4.0, "lens_f_number": 2.0, "sensor_pitch_um": 1.55, "doe_pitch_um": 2.0}


def _wide(tmp_path, optics="", design=""):
    """A 16 mm lens with 1.55 µm pixels and 2 µm DOE pixels (the default period: 16 of them, 32 µm)."""
    path = tmp_path / "wide.toml"
    path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\n'
                    + "".join(f"{k} = {v}\n" for k, v in WIDE.items()) + f"[optics]\n{optics}[design]\n{design}")
    return load_scene(path)


def _refusal(scene) -> str:
    with pytest.raises(doefab.DoefabError) as e:
        resolve(scene)
    return str(e.value)


def test_a_first_order_beyond_the_window_names_the_shortest_period_that_brings_it_inside(tmp_path):
    """The default 32 µm period puts 700 nm ~227 px off axis, beyond the 191 px window (which holds 95 − 1 − 2 =
    92 px with the metric box and its margin): the refusal names the least window that holds it (2·⌈227 + 1 + 2⌉ + 1)
    and the shortest period whose 700 nm order lands within it, to 0.01 µm; that period passes, 0.01 µm less does
    not."""
    msg = _refusal(_wide(tmp_path))
    found = re.search(r"lands (\d+) px off axis: raise kernel_px to ≥ (\d+), or keep it and set "
                      r"design\.grating_period_um ≥ ([\d.]+) \(µm\)", msg)
    assert found, msg
    period_um = float(found.group(3))
    s = resolve(_wide(tmp_path, design=f"grating_period_um = {period_um}\n")).camera.sensor_distance
    far = _far_px(s, 1.55e-6, 32e-6)
    assert int(found.group(1)) == round(far) and int(found.group(2)) == 2 * math.ceil(far + 3) + 1
    assert _far_px(s, 1.55e-6, period_um * 1e-6) <= 92 < _far_px(s, 1.55e-6, (period_um - 0.01) * 1e-6)
    assert (found.group(1), found.group(2), found.group(3)) == ("227", "461", "78.8")  # the guide's example
    assert "first order lands 92 px off axis" in _refusal(_wide(tmp_path, design=f"grating_period_um = "
                                                                                 f"{period_um - 0.01:.2f}\n"))


@pytest.mark.parametrize("bands, named", [(60, True), (61, False)])
def test_the_longer_period_is_named_only_where_the_bands_stay_at_most_one_and_a_half_per_pixel(tmp_path, bands,
                                                                                              named):
    """400–700 nm in evenly spaced bands through the period that brings 700 nm within 92 px: the orders spread
    over 39.4 px, so 60 bands are 1.496 per pixel (named) and 61 are 1.522 (only the wider window is named)."""
    lams = ", ".join(f"{400 + 300 * i / (bands - 1):.4f}" for i in range(bands))
    msg = _refusal(_wide(tmp_path, optics=f"wavelengths_nm = [{lams}]\n"))
    assert "first order lands" in msg and ("grating_period_um" in msg) == named, msg
    period_um = 78.8  # the period the 31-band scene is told (test above): the same reach, the same 700 nm
    sd = resolve(_wide(tmp_path, design=f"grating_period_um = {period_um}\n")).camera.sensor_distance
    spread = _far_px(sd, 1.55e-6, period_um * 1e-6) - _far_px(sd, 1.55e-6, period_um * 1e-6, 400e-9)
    assert ((bands - 1) / spread <= 1.5) == named  # the reason, by the grating equation written out here


def test_no_period_is_named_beyond_the_keys_range(tmp_path):
    """One band at 700 nm, a 15 px window and a 4 px metric box through a 50 mm lens on 1 µm pixels: the order must
    land within 7 − 4 − 2 = 1 px, which needs Λ ≈ 35 mm, beyond design.grating_period_um's 10 000 µm."""
    path = tmp_path / "tiny.toml"
    path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\nfocal_length_mm = 50.0\n'
                    'sensor_pitch_um = 1.0\ndoe_pitch_um = 2.0\n[optics]\nwavelengths_nm = [700]\nkernel_px = 15\n'
                    '[design]\ngrating_box_px = 4\n')
    msg = _refusal(load_scene(path))
    assert "first order lands" in msg and "grating_period_um" not in msg, msg


def test_a_period_without_a_first_order_is_refused_in_the_api_and_the_scene(tmp_path):
    """sin θ = λ / Λ: a 0.6 µm period sends no first order at 700 nm (the key's range starts at 0.5 µm)."""
    from doefab.tasks.grating import GratingTask

    cam = doefab.Camera(doe_pitch=2e-6, doe_pixels=4320)
    with pytest.raises(doefab.DoefabError, match="no first order at 700 nm"):
        GratingTask(period_m=0.6e-6).bind(cam)
    with pytest.raises(doefab.DoefabError, match="from where the lens sends it"):  # it has one, far off axis
        GratingTask(period_m=0.71e-6).bind(cam)
    msg = _refusal(_wide(tmp_path, design="grating_period_um = 0.6\n"))
    assert "no first order at 700 nm" in msg and "design.grating_period_um" in msg, msg


@pytest.mark.parametrize("stages", [["design", "masks"], ["design", "reconstruction"]])
def test_a_near_infrared_grating_is_designed_and_refused_only_where_its_networks_would_need_scenes(tmp_path, stages):
    """800–1000 nm through a 25 mm lens: the design and its masks take the bands alone; the hyperspectral scenes
    (400–700 nm) and the camera's default RGB response (380–780 nm) bound the bands only where a reconstruction
    stage is asked for."""
    path = tmp_path / "nir.toml"
    listed = ", ".join(f'"{s}"' for s in stages)
    path.write_text(f'task = "hyperspectral"\nstages = [{listed}]\n[camera]\nfocal_length_mm = 25.0\nf_number = 4.0\n'
                    'lens_f_number = 2.0\nfocus_distance_m = 5.0\nsensor_pitch_um = 5.0\ndoe_pitch_um = 4.0\n'
                    '[optics]\nwavelengths_nm = [800, 900, 1000]\n[design]\ngrating_period_um = 64.0\n'
                    '[fabrication]\nmaterial = "fused silica"\ndesign_wavelength_nm = 900\n')
    scene = load_scene(path)
    if "reconstruction" not in stages:
        assert resolve(scene).task.wavelengths(resolve(scene).camera) == pytest.approx((800e-9, 900e-9, 1000e-9))
        return
    msg = _refusal(scene)
    assert "known on 400–700 nm" in msg and "leave \"reconstruction\" out of stages" in msg, msg
    assert "380–780 nm" in msg, msg


def test_no_period_is_named_where_the_one_that_spreads_the_bands_diffracts_beyond_the_model(tmp_path):
    """A 5 mm lens on 10 µm pixels (s/p ≈ 500): spreading 400–700 nm over 30 px needs Λ = s·300 nm/(30 p) ≈ 5 µm,
    where s·(tan θ − sin θ)/p at 700 nm is 0.7 px, beyond the 0.5 px the model holds: the note names no period, and
    that period is indeed refused."""
    path = tmp_path / "s.toml"
    path.write_text('task = "hyperspectral"\nstages = ["design"]\n[camera]\nfocal_length_mm = 5.0\nf_number = 2.8\n'
                    'lens_f_number = 2.8\nfocus_distance_m = 5.0\nsensor_pitch_um = 10.0\ndoe_pitch_um = 1.0\n'
                    '[optics]\nkernel_px = 191\n[design]\ngrating_period_um = 40.0\n')
    res = resolve(load_scene(path))
    _, meaning = _sampling(res)
    assert "no grating period spreads them one per pixel within the model" in meaning, meaning
    assert "design.grating_period_um =" not in meaning
    s, p = res.camera.sensor_distance, 10e-6
    spread = s * 300e-9 / (30 * p)
    x = 700e-9 / spread
    assert s * (x / math.sqrt(1 - x * x) - x) / p > 0.5
    path.write_text(path.read_text().replace("grating_period_um = 40.0", f"grating_period_um = {spread * 1e6:.2f}"))
    with pytest.raises(doefab.DoefabError, match="from where the lens sends it"):
        resolve(load_scene(path))
