"""A scene's own sensor: its response and noise reach the checks, the doctor, the stage hashes and the choice of
networks (the shipped ones are for the prototype's sensor)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from doefab.cli import main
from doefab.errors import DoefabError
from doefab.pipeline.doctor import explain
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

REPO = Path(__file__).resolve().parents[2]


def _scene(tmp: Path, name: str, sensor: str, stages=None) -> Path:
    text = (REPO / "scenes" / f"{name}.toml").read_text()
    if stages is not None:
        text = "\n".join(f"stages = {stages}" if ln.startswith("stages =") else ln for ln in text.splitlines())
    p = tmp / f"{name}.toml"
    p.write_text(text + f"\n[sensor]\n{sensor}\n")
    return p


def test_a_response_that_misses_the_bands_is_refused_before_any_work(tmp_path):
    with pytest.raises(DoefabError) as exc:
        resolve(load_scene(_scene(tmp_path, "hyperspectral", 'response = "Sigma SD Merrill"')))
    assert "sensor.response" in str(exc.value) and "400–680 nm" in str(exc.value)


def test_a_csv_response_is_found_beside_the_scene_and_named_by_its_file(tmp_path):
    lam = np.arange(380, 781, 5.0)
    rows = np.column_stack([lam] + [np.exp(-0.5 * ((lam - mu) / 30) ** 2) for mu in (600, 540, 460)])
    np.savetxt(tmp_path / "cam.csv", rows, delimiter=",", header="wavelength_nm,R,G,B", comments="")
    res = resolve(load_scene(_scene(tmp_path, "hyperspectral", 'response = "cam.csv"')))
    assert res.sensor.record()["response"] == "cam.csv (CSV)"
    assert res.reuse  # the design does not depend on the sensor


def test_the_doctor_states_the_noise_the_sensor_implies(tmp_path):
    """The SNR at full scale against the sensor's own noise drawn at a capture value of 1 (200 000 pixels)."""
    res = resolve(load_scene(_scene(tmp_path, "hdr", "full_well_e = 12000.0\nread_noise_e = 1.5")))
    rows = {r["quantity"]: r["value"] for r in explain(res)}
    full = res.sensor.noise().apply(np.ones(200_000), np.random.default_rng(0))
    assert rows["shot-noise SNR at full scale"] == pytest.approx(full.mean() / full.std(), rel=0.01)
    assert rows["capture dynamic range"] == pytest.approx(math.log2(12000 / 1.5))


def test_an_rgb_task_warns_that_the_response_is_not_used(tmp_path):
    res = resolve(load_scene(_scene(tmp_path, "depth", 'response = "Nikon D5100"')))
    assert any("not used by the depth task" in w for w in res.warnings)


def test_the_reconstruction_stage_hash_follows_the_csv_content(tmp_path):
    from doefab.pipeline.stagerun import stage_hash

    lam = np.arange(380, 781, 5.0)
    hashes = []
    for scale in (1.0, 0.5):
        rows = np.column_stack([lam] + [np.exp(-0.5 * ((lam - mu) / 30) ** 2) * (scale if mu == 600 else 1)
                                        for mu in (600, 540, 460)])
        np.savetxt(tmp_path / "cam.csv", rows, delimiter=",", header="wavelength_nm,R,G,B", comments="")
        scene = load_scene(_scene(tmp_path, "hyperspectral", 'response = "cam.csv"'))
        hashes.append((stage_hash(scene, "reconstruction", {}, False), stage_hash(scene, "design", {}, False)))
    assert hashes[0][0] != hashes[1][0] and hashes[0][1] == hashes[1][1]


def test_the_default_sensor_written_out_changes_no_stage(tmp_path, monkeypatch):
    """A [sensor] section that states the default values leaves every stage's hash as without it, and no stage
    hashes a sensor then (runs made before sensors existed are kept); another noise changes the reconstruction
    and tolerance stages only."""
    import doefab.pipeline.stagerun as stages
    from doefab.pipeline.stagerun import stage_hash

    hashed = []
    real = stages._h
    monkeypatch.setattr(stages, "_h", lambda obj: hashed.append(obj) or real(obj))

    plain = load_scene(REPO / "scenes" / "hdr.toml")
    stated = load_scene(_scene(tmp_path, "hdr", "full_well_e = 25000.0\nread_noise_e = 3.0"))
    (tmp_path / "other").mkdir()
    other = load_scene(_scene(tmp_path / "other", "hdr", "full_well_e = 20000.0"))
    for name in ("design", "reconstruction", "tolerance"):
        assert stage_hash(stated, name, {}, False) == stage_hash(plain, name, {}, False), name
    stage_parts = [p for p in hashed if "upstream" in p]  # not the budget's digest (its own [sensor] table)
    assert len(stage_parts) == 6 and not any("sensor" in parts for parts in stage_parts)
    assert stage_hash(other, "design", {}, False) == stage_hash(plain, "design", {}, False)
    assert stage_hash(other, "reconstruction", {}, False) != stage_hash(plain, "reconstruction", {}, False)
    assert stage_hash(other, "tolerance", {}, False) != stage_hash(plain, "tolerance", {}, False)


def test_shipped_networks_are_not_used_for_another_sensors_noise(tmp_path, monkeypatch):
    monkeypatch.setenv("DOEFAB_CACHE", str(tmp_path / "cache"))
    scene = _scene(tmp_path, "hdr", "read_noise_e = 20.0", stages='["design", "reconstruction"]')
    assert main(["run", str(scene), "--quick", "--out", str(tmp_path / "out")]) == 0
    st = json.loads((tmp_path / "out" / "reconstruction" / "stage.json").read_text())
    assert st["status"] == "skipped" and "another sensor" in st["why"] and "read_noise_e 3 (this camera: 20)" in st[
        "why"]
