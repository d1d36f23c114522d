"""The main job on a tiny camera that is not the prototype: a new design, networks trained for it (their records
name its level map), the shipped networks refused for it unless asked for with a warning."""

import json

import pytest

from doefab.cli import main
from doefab.design.design import Design, levels_sha256

TINY = """task = "hdr"
stages = ["design", "reconstruction"]
[camera]
focal_length_mm = 20.0
aperture_diameter_mm = 1.0
sensor_pitch_um = 5.0
doe_pitch_um = 10.0
focus_distance_m = 5.0
[optics]
kernel_px = 31
[design]
streak_arm_px = 8
[fabrication]
n_levels = 4
[reconstruction]
weights = "{weights}"
"""


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tiny")
    mp = pytest.MonkeyPatch()
    mp.setenv("DOEFAB_CACHE", str(tmp / "cache"))
    scene = tmp / "tiny.toml"
    scene.write_text(TINY.format(weights="train"))
    assert main(["run", str(scene), "--quick", "--out", str(tmp / "out")]) == 0
    yield tmp
    mp.undo()


def _stages(out) -> dict:
    run = json.loads((out / "run.json").read_text())["stages"]
    return {name: {**run[name], **json.loads((out / name / "stage.json").read_text())} for name in run}


def test_networks_are_trained_for_the_scenes_design(trained):
    st = _stages(trained / "out")
    assert st["design"]["status"] == "ran" and st["reconstruction"]["weights"] == "train"
    d = Design.load(trained / "out" / "design")
    assert d.n_levels == 4 and d.camera.doe_pixels == 100
    sha = levels_sha256(d.levels)
    for v in ("proposed", "coded_only", "uncoded_only"):
        meta = json.loads((trained / "out" / "reconstruction" / "weights" / f"hdr_{v}.json").read_text())
        assert meta["design_levels_sha256"] == sha, v
        assert meta["training"]["warm_start"]["tensors"] > 0  # the shipped network's shapes fit
    assert set(st["reconstruction"]["rows"]) == {"proposed", "coded_only", "uncoded_only"}
    assert st["reconstruction"]["design_levels_sha256"] == sha


def test_shipped_networks_are_refused_for_a_new_design_unless_asked_for(trained, capsys):
    scene = trained / "tiny.toml"
    scene.write_text(TINY.format(weights="shipped"))
    assert main(["run", str(scene), "--quick", "--out", str(trained / "out")]) == 0
    st = _stages(trained / "out")
    assert st["reconstruction"]["status"] == "skipped" and "shipped-anyway" in st["reconstruction"]["why"]
    scene.write_text(TINY.format(weights="shipped-anyway"))
    assert main(["run", str(scene), "--quick", "--out", str(trained / "out")]) == 0
    st = _stages(trained / "out")
    assert st["design"].get("reused_from_previous_run")
    assert st["reconstruction"]["why"].startswith("WARNING") and st["reconstruction"]["weights"] == "shipped-anyway"
