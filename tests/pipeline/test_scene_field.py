"""The holder's hole passes the field the scene's sensor sees: ``camera.sensor_diagonal_mm`` sets the flare's
half-angle unless the holder gives one; a field wider than a supportless flare is refused by doctor and run."""

import math

import pytest

from doefab.errors import DoefabError
from doefab.pipeline import stagerun
from doefab.pipeline.scene import load_scene
from doefab.pipeline.sceneholder import scene_holder
from doefab.pipeline.system import resolve


def _scene(tmp_path, camera: str = "", holder: str = "", name: str = "s.toml"):
    p = tmp_path / name
    p.write_text(f'task = "hdr"\nstages = ["design", "masks", "holder"]\n[camera]\nfocal_length_mm = 50.0\n'
                 f"focus_distance_m = 5.0\n{camera}\n[holder]\nthread_diameter_mm = 49.0\n{holder}\n")
    return load_scene(p)


def test_the_sensor_diagonal_sets_the_holders_field(tmp_path):
    scene = _scene(tmp_path, "sensor_diagonal_mm = 43.27")
    res = resolve(scene)
    image_mm = 1 / (1 / 50.0 - 1 / 5000.0)  # thin lens: 50 mm focused at 5 m puts the sensor 50.505 mm behind it
    expected = math.degrees(math.atan(43.27 / 2 / image_mm))  # 23.19°: a full-frame sensor's corner
    assert scene_holder(scene, res.camera)["field_half_angle_deg"] == pytest.approx(expected, abs=1e-3)
    # a given half-angle wins; without either, the holder keeps its own default
    given = _scene(tmp_path, "sensor_diagonal_mm = 43.27", "field_half_angle_deg = 10.0", "g.toml")
    assert scene_holder(given, resolve(given).camera)["field_half_angle_deg"] == 10.0
    from doefab.pipeline.report import system_table  # the run report's system table says the same

    assert any(r[0].startswith("field the holder's hole passes") and r[1] == f"{expected:.4g} °"
               for r in system_table(res, scene))
    plain = _scene(tmp_path, name="p.toml")
    assert "field_half_angle_deg" not in scene_holder(plain, resolve(plain).camera)
    # the holder stage (and the masks' die, which the flare can widen) rerun for another sensor
    small = _scene(tmp_path, "sensor_diagonal_mm = 7.7", name="phone.toml")
    hashes = {s.path.name: stagerun.stage_hash(s, "holder", {}, False) for s in (scene, small, plain)}
    assert len(set(hashes.values())) == 3


def test_a_field_wider_than_the_flare_prints_is_refused(tmp_path):
    scene = _scene(tmp_path, "sensor_diagonal_mm = 150")  # 56° off the axis at 50.5 mm
    with pytest.raises(DoefabError, match=r"camera.sensor_diagonal_mm 150 .* more than the 45° .* set "
                                          r"holder.field_half_angle_deg"):
        resolve(scene)
    resolve(_scene(tmp_path, "sensor_diagonal_mm = 150", "field_half_angle_deg = 25.0", "ok.toml"))
    # a field the cartridge's flare cannot pass with wall_mm round it says which key set it
    wide = _scene(tmp_path, "sensor_diagonal_mm = 43.3", name="wide.toml")
    wide.camera["focal_length_mm"] = 24.0
    with pytest.raises(DoefabError, match=r"set field_half_angle_deg = [\d.]+ or less .* follows from "
                                          r"camera.sensor_diagonal_mm"):
        resolve(wide)
