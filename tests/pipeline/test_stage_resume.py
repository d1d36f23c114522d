"""Issue 21, row 10 and "no work lost to an interruption": a stage interrupted mid-way keeps what it had saved
(the design's optimiser checkpoint, the networks' training checkpoints, the tolerance study's parts and finished
steps) when it is rerun with the same inputs, and starts afresh when its inputs changed."""

from types import SimpleNamespace

import pytest

from doefab.io import mark_folder
from doefab.pipeline import stages


def _interrupted(root, name, scene, files):
    """A stage folder as an interrupted run leaves it: marked, its record incomplete, its saved work present."""
    out = root / name
    out.mkdir(parents=True)
    mark_folder(out, stages.STAGE_KIND, stage=name)
    h = stages.stage_hash(scene, name, {}, False)
    (out / "stage.json").write_text(f'{{"stage": "{name}", "hash": "{h}", "complete": false}}')
    for f in files:
        (out / f).write_bytes(f"saved {f}".encode())
    (out / "partial_figure.png").write_bytes(b"not kept")
    return out


@pytest.mark.parametrize("name", sorted(stages.RESUMABLE))
def test_a_rerun_with_the_same_inputs_continues_from_the_saved_work(tmp_path, monkeypatch, name):
    scene = SimpleNamespace(raw={"design": {"iterations": 60}}, task="hdr")
    files = stages.RESUMABLE[name]
    _interrupted(tmp_path, name, scene, files)
    assert stages.has_progress(tmp_path, [name])
    seen = {}

    def fake(scene, res, out, quick):
        seen.update({f: (out / f).read_bytes() for f in files if (out / f).exists()})
        seen["figure"] = (out / "partial_figure.png").exists()
        return {"status": "ran", "why": "fake"}

    monkeypatch.setitem(stages.STAGE_FUNCS, name, fake)
    info = stages.run_stage(scene, {}, name, tmp_path, {}, False, force=False)
    assert {f: seen[f] for f in files} == {f: f"saved {f}".encode() for f in files}
    assert seen["figure"] is False  # what is not resumable is recomputed
    assert "continued from the interrupted run" in info["why"] and info["complete"]


@pytest.mark.parametrize("name", sorted(stages.RESUMABLE))
def test_changed_inputs_or_force_start_afresh(tmp_path, monkeypatch, name):
    scene = SimpleNamespace(raw={"design": {"iterations": 60}}, task="hdr")
    files = stages.RESUMABLE[name]
    seen = {}
    monkeypatch.setitem(stages.STAGE_FUNCS, name, lambda scene, res, out, quick: seen.update(
        kept=[f for f in files if (out / f).exists()]) or {"status": "ran", "why": "fake"})
    _interrupted(tmp_path / "a", name, scene, files)
    changed = SimpleNamespace(raw={"design": {"iterations": 61}, name: {"x": 1}, "fabrication": {"levels": 8}},
                              task="hdr")
    stages.run_stage(changed, {}, name, tmp_path / "a", {}, False, force=False)
    assert seen["kept"] == []
    _interrupted(tmp_path / "b", name, scene, files)
    stages.run_stage(scene, {}, name, tmp_path / "b", {}, False, force=True)
    assert seen["kept"] == []


def test_the_design_stage_resumes_the_optimiser_from_its_checkpoint(tmp_path, monkeypatch):
    import doefab

    got = {}

    class Stop(Exception):
        pass

    def fake_optimize(*a, **kw):
        got.update(kw)
        raise Stop

    monkeypatch.setattr(doefab, "optimize", fake_optimize)
    monkeypatch.setattr(stages, "redesign_note", lambda res, quick: "a new design")
    settings = {"iterations": 5, "sampling": 1, "optimizer": "adam", "seed": 0, "design_task": "streak",
                "parameterization": "pixel", "knots": 0, "levels": 16}
    res = {"reuse": False, "settings": settings, "task": SimpleNamespace(params=lambda: {}), "camera": None}
    for saved in (False, True):
        out = tmp_path / str(saved)
        out.mkdir()
        if saved:
            (out / "checkpoint.pt").write_bytes(b"x")
        with pytest.raises(Stop):
            stages.stage_design(SimpleNamespace(), res, out, False)
        assert got["resume"] is saved and got["out_dir"] == out


def test_the_design_hash_follows_the_fabrication_and_the_tolerance_hash_its_networks():
    """Levels or substrate change the design; retrained networks change what the tolerance study judges."""
    a = SimpleNamespace(raw={"fabrication": {"levels": 16}}, task="hdr")
    b = SimpleNamespace(raw={"fabrication": {"levels": 8}}, task="hdr")
    assert stages.stage_hash(a, "design", {}, False) != stages.stage_hash(b, "design", {}, False)
    one, two = {"reconstruction": {"hash": "1"}}, {"reconstruction": {"hash": "2"}}
    assert stages.stage_hash(a, "tolerance", one, False) != stages.stage_hash(a, "tolerance", two, False)
