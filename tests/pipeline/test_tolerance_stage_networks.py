"""Which networks the tolerance stage judges its parts through: those the scene's reconstruction stage trained for
this very design and sensor, else the shipped ones where they fit the system, else none (PSF level). Networks
an earlier run trained for another design or sensor, left in the run folder, are never used."""

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import doefab
from doefab.design.design import Design, levels_sha256
from doefab.imaging.sensor import Sensor
from doefab.pipeline import stages
from doefab.pipeline.scene import load_scene
from doefab.reconstruction.weights import WEIGHTS_FORMAT

REPO = Path(__file__).resolve().parents[2]


def _design(folder: Path, seed: int) -> str:
    cam = doefab.Camera(aperture_diameter=0.2e-3, doe_pitch=5.4e-6, doe_pixels=40, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    lv = np.random.default_rng(seed).integers(0, 16, (40, 40)).astype(np.uint8)
    d = Design(task="streak", task_params={"kernel_size": 31, "arm_px": 8}, camera=cam, wavelengths=(550e-9,),
               depths=(5.0,), height=doefab.levels_to_height(lv, cam), levels=lv,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d.save(folder)
    return levels_sha256(lv)


def _run_folder(tmp_path, mode: str, trained_for: str, sensor: dict | None = None) -> Path:
    """A run folder whose reconstruction stage ran with ``mode`` and whose weights' record says they are for
    ``trained_for`` ("this" design or an "other" one) and ``sensor`` (None: the default sensor)."""
    root = tmp_path / "run"
    _design(root / "design", 0)
    other = _design(tmp_path / "other_design", 1)
    _write_weights(root, _design_sha(root) if trained_for == "this" else other, sensor)
    (root / "reconstruction" / "stage.json").write_text(json.dumps(
        {"stage": "reconstruction", "complete": True, "weights": mode, "hash": "1" * 16}))
    return root


def _write_weights(root: Path, design_sha: str, sensor: dict | None = None) -> None:
    """The proposed network's file and its record, as ``train`` writes them (the file's bytes are not a network:
    the tolerance stage reads the record only)."""
    folder = root / "reconstruction" / "weights"
    folder.mkdir(parents=True, exist_ok=True)
    data = b"weights"
    (folder / "hdr_proposed.pt").write_bytes(data)
    meta = {"format": WEIGHTS_FORMAT, "task": "hdr", "variant": "proposed", "design_levels_sha256": design_sha,
            "arch": {}, "weights_sha256": hashlib.sha256(data).hexdigest(),
            "sensor": sensor or Sensor().record(with_response=False)}
    (folder / "hdr_proposed.json").write_text(json.dumps(meta))


def _design_sha(root: Path) -> str:
    return levels_sha256(Design.load(root / "design").levels)


def _judged_by(root: Path, monkeypatch, reuse: bool) -> tuple[dict, str]:
    import doefab.tolerance.report as report

    seen = {}

    def spy(design_dir, budget, out, **kw):
        seen.update(kw)
        return {"summary": None, "level": "network" if kw["networks"] else "psf"}

    monkeypatch.setattr(report, "run_study", spy)
    info = stages.stage_tolerance(load_scene(REPO / "scenes" / "hdr.toml"), SimpleNamespace(reuse=reuse, sensor=None),
                                  root / "tolerance", True)
    return seen, info["why"]


def test_the_networks_this_scene_trained_for_its_design_judge_it(tmp_path, monkeypatch):
    root = _run_folder(tmp_path, "train", "this")
    for reuse in (True, False):  # before the shipped ones too, where those would fit
        seen, why = _judged_by(root, monkeypatch, reuse)
        assert seen["networks"] and seen["weights_dir"] == root / "reconstruction" / "weights"
        assert "through the networks this scene trained" in why


@pytest.mark.parametrize("trained_for, sensor, words", [
    ("other", None, "trained for another design"),
    ("this", {"full_well_e": 900.0, "read_noise_e": 7.0}, "trained for another sensor"),
])
def test_networks_left_from_another_system_are_never_used(tmp_path, monkeypatch, trained_for, sensor, words):
    root = _run_folder(tmp_path, "train", trained_for, sensor)
    seen, why = _judged_by(root, monkeypatch, reuse=False)  # a new design: no shipped network fits it
    assert seen["networks"] is False and seen["weights_dir"] is None
    assert words in why and "run the reconstruction stage" in why and "at PSF level" in why
    seen, why = _judged_by(root, monkeypatch, reuse=True)  # the committed design: the shipped networks fit
    assert seen["networks"] and seen["weights_dir"] is None and "through the shipped networks" in why


def test_a_stage_that_trained_nothing_lends_no_networks(tmp_path, monkeypatch):
    root = _run_folder(tmp_path, "shipped-anyway", "this")  # a weights folder it did not write
    seen, why = _judged_by(root, monkeypatch, reuse=False)
    assert seen["networks"] is False and "trained for" not in why


def test_the_stage_is_judged_again_when_the_networks_it_would_use_change(tmp_path):
    """A tolerance stage that judged at PSF level because the networks were stale runs again once the
    reconstruction stage has trained this design's (also in a run of that stage alone), and again when they are
    retrained."""
    from doefab.pipeline.stagerun import stage_hash

    scene, res = load_scene(REPO / "scenes" / "hdr.toml"), SimpleNamespace(reuse=False, sensor=None)
    root = _run_folder(tmp_path, "train", "other")
    record = root / "reconstruction" / "stage.json"
    stale = stage_hash(scene, "tolerance", {}, False, res, root)
    assert stage_hash(scene, "tolerance", {}, False, res, root) == stale
    _write_weights(root, _design_sha(root))  # trained for this design by a run of the reconstruction stage
    trained = stage_hash(scene, "tolerance", {}, False, res, root)
    record.write_text(json.dumps({**json.loads(record.read_text()), "hash": "2" * 16}))  # and retrained
    assert len({stale, trained, stage_hash(scene, "tolerance", {}, False, res, root)}) == 3


def test_the_stage_says_where_its_mounting_errors_come_from(tmp_path, monkeypatch):
    """The shipped budget's mounting errors are a 3D-printed filter-thread holder's: a scene that builds no holder
    and keeps that budget, or leaves mounting keys out of its own, is told so, with the key to change; one whose
    run built its holder, or whose budget sets every mounting key, is not."""
    import doefab.pipeline.stages as st
    import doefab.tolerance.errors as errors

    root = _run_folder(tmp_path, "train", "this")
    _, why = _judged_by(root, monkeypatch, reuse=True)  # no holder.json beside the design, the default budget
    assert "mounting errors from the shipped budget's 3D-printed filter-thread holder" in why
    assert "set tolerance.budget" in why
    (root / "holder").mkdir()
    (root / "holder" / "holder.json").write_text("{}")
    monkeypatch.setattr(errors, "holder_mounting", lambda path: {"decenter_max_mm": 0.1})
    _, why = _judged_by(root, monkeypatch, reuse=True)
    assert "mounting errors from this run's holder" in why and "tolerance.budget" not in why
    shipped = errors.DEFAULT_BUDGET.read_text()
    own = tmp_path / "lab_budget.toml"
    own.write_text(shipped)  # every key spelt out: nothing taken from the shipped file
    assert st._mounting_note(False, own, errors.load_budget(own)) == ""
    own.write_text(shipped.replace("decenter_max_mm = 0.25\n", ""))  # one mounting key left out
    note = st._mounting_note(False, own, errors.load_budget(own))
    assert "mounting.decenter_max_mm (left out of lab_budget.toml) from the shipped budget's" in note
    assert st._mounting_note(False, errors.DEFAULT_BUDGET, errors.load_budget(errors.DEFAULT_BUDGET)).startswith(
        "; mounting errors from the shipped budget's")  # the shipped file named by its path
