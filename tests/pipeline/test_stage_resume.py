"""Issue 21, row 10 and "no work lost to an interruption": a stage interrupted mid-way keeps what it had saved
(the design's optimiser checkpoint, the networks' training checkpoints, the tolerance study's parts and finished
steps) when it is rerun with the same inputs, and starts afresh when its inputs changed."""

from types import SimpleNamespace

import pytest

from doefab.io import mark_folder
from doefab.pipeline import stagerun, stages
from doefab.pipeline.knobs import REPO


SAVED = {"design": ("checkpoint.pt", "history.csv"),
         "reconstruction": ("run_proposed/checkpoint.pt", "run_coded_only/history.csv", "weights/hdr_proposed.pt"),
         "tolerance": ("samples.jsonl", "steps/grid.json", "steps/tornado.json")}


def _res(scene):
    """A resolved scene as the stage cache reads it: the design settings the scene asks for."""
    return SimpleNamespace(design_key=lambda: {"settings": scene.raw.get("design")})


def _interrupted(root, name, scene, files):
    """A stage folder as an interrupted run leaves it: marked, its record incomplete, its saved work present."""
    out = root / name
    out.mkdir(parents=True)
    mark_folder(out, stagerun.STAGE_KIND, stage=name)
    h = stagerun.stage_hash(scene, name, {}, False, _res(scene))
    (out / "stage.json").write_text(f'{{"stage": "{name}", "hash": "{h}", "complete": false}}')
    for f in files:
        (out / f).parent.mkdir(parents=True, exist_ok=True)
        (out / f).write_bytes(f"saved {f}".encode())
    (out / "partial_figure.png").write_bytes(b"not kept")
    return out


@pytest.mark.parametrize("name", sorted(stagerun.RESUMABLE))
def test_a_rerun_with_the_same_inputs_continues_from_the_saved_work(tmp_path, monkeypatch, name):
    scene = SimpleNamespace(raw={"design": {"iterations": 60}}, task="hdr")
    files = SAVED[name]
    _interrupted(tmp_path, name, scene, files)
    assert stagerun.has_progress(tmp_path, [name])
    seen = {}

    def fake(scene, res, out, quick):
        seen.update({f: (out / f).read_bytes() for f in files if (out / f).exists()})
        seen["figure"] = (out / "partial_figure.png").exists()
        return {"status": "ran", "why": "fake"}

    monkeypatch.setitem(stagerun.STAGE_FUNCS, name, fake)
    info = stagerun.run_stage(scene, _res(scene), name, tmp_path, {}, False, force=False)
    assert {f: seen[f] for f in files} == {f: f"saved {f}".encode() for f in files}
    assert seen["figure"] is False  # what is not resumable is recomputed
    assert "continued from the interrupted run" in info["why"] and info["complete"]


def test_a_failed_run_with_nothing_resumable_is_not_kept(tmp_path):
    """A copied history.csv or an empty training folder is not progress; a checkpoint is."""
    (tmp_path / "design").mkdir()
    (tmp_path / "design" / "history.csv").write_text("copied from the committed design")
    (tmp_path / "reconstruction" / "run_proposed").mkdir(parents=True)
    assert not stagerun.has_progress(tmp_path, ["design", "reconstruction"])
    (tmp_path / "reconstruction" / "run_proposed" / "checkpoint.pt").write_bytes(b"x")
    assert stagerun.has_progress(tmp_path, ["design", "reconstruction"])


def test_a_tolerance_study_interrupted_in_its_first_step_has_progress(tmp_path):
    """A study interrupted before any step was kept whole holds only the parts of that step
    (steps/<step>.parts.jsonl, ``partmemo.memo_step``): that is work worth keeping, as a finished step is."""
    (tmp_path / "tolerance" / "steps").mkdir(parents=True)
    assert not stagerun.has_progress(tmp_path, ["tolerance"])
    (tmp_path / "tolerance" / "steps" / "grid.parts.jsonl").write_text('{"key": {}}\n{"part": "mask overlay"}\n')
    assert stagerun.has_progress(tmp_path, ["tolerance"])


@pytest.mark.parametrize("name", sorted(stagerun.RESUMABLE))
def test_changed_inputs_or_force_start_afresh(tmp_path, monkeypatch, name):
    scene = SimpleNamespace(raw={"design": {"iterations": 60}}, task="hdr")
    files = SAVED[name]
    seen = {}
    monkeypatch.setitem(stagerun.STAGE_FUNCS, name, lambda scene, res, out, quick: seen.update(
        kept=[f for f in files if (out / f).exists()]) or {"status": "ran", "why": "fake"})
    _interrupted(tmp_path / "a", name, scene, files)
    changed = SimpleNamespace(raw={"design": {"iterations": 61}, name: {"x": 1}, "fabrication": {"n_levels": 8}},
                              task="hdr")
    stagerun.run_stage(changed, _res(changed), name, tmp_path / "a", {}, False, force=False)
    assert seen["kept"] == []
    _interrupted(tmp_path / "b", name, scene, files)
    stagerun.run_stage(scene, _res(scene), name, tmp_path / "b", {}, False, force=True)
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
                "parameterization": "pixel", "knots": 0, "n_levels": 16}
    res = SimpleNamespace(reuse=False, settings=settings, task=SimpleNamespace(params=lambda: {}), camera=None,
                          quick_sampling=None)
    for saved in (False, True):
        out = tmp_path / str(saved)
        out.mkdir()
        if saved:
            (out / "checkpoint.pt").write_bytes(b"x")
        with pytest.raises(Stop):
            stages.stage_design(SimpleNamespace(), res, out, False)
        assert got["resume"] is saved and got["out_dir"] == out


def test_the_design_hash_follows_the_fabrication_and_the_tolerance_hash_its_networks(tmp_path):
    """Levels change the design, a default written out does not (one definition of the same scene: the resolved
    design settings); retrained networks change what the tolerance study judges."""
    from doefab.pipeline.scene import load_scene

    text = (REPO / "scenes" / "hdr.toml").read_text()
    assert "n_levels = 16" in text and "seed = 0" in text
    files = {"a": text, "b": text.replace("n_levels = 16", "n_levels = 8"),
             "same": text.replace("seed = 0\n", "")}  # the seed's default, left out
    for name, t in files.items():
        (tmp_path / f"{name}.toml").write_text(t)
    a, b, same = (load_scene(tmp_path / f"{n}.toml") for n in files)
    assert "seed" not in same.raw["design"]
    assert stagerun.stage_hash(a, "design", {}, False) != stagerun.stage_hash(b, "design", {}, False)
    assert stagerun.stage_hash(a, "design", {}, False) == stagerun.stage_hash(same, "design", {}, False)
    one, two = {"reconstruction": {"hash": "1"}}, {"reconstruction": {"hash": "2"}}
    assert stagerun.stage_hash(a, "tolerance", one, False) != stagerun.stage_hash(a, "tolerance", two, False)
    # the scene size the network judge reads each part at, also in a run without a reconstruction stage
    assert "size_px = 256" in text
    (tmp_path / "small.toml").write_text(text.replace("size_px = 256", "size_px = 128"))
    small = load_scene(tmp_path / "small.toml")
    assert stagerun.stage_hash(a, "tolerance", {}, False) != stagerun.stage_hash(small, "tolerance", {}, False)
    # a wider aperture margin in the holder's pocket needs a larger die: the masks change, the design does not
    (tmp_path / "margin.toml").write_text(text.replace("[holder]\n", "[holder]\naperture_margin_mm = 3.0\n"))
    margin = load_scene(tmp_path / "margin.toml")
    assert stagerun.stage_hash(a, "masks", {}, False) != stagerun.stage_hash(margin, "masks", {}, False)
    assert stagerun.stage_hash(a, "design", {}, False) == stagerun.stage_hash(margin, "design", {}, False)


def test_editing_the_budget_file_changes_the_stages_that_draw_parts_from_it(tmp_path):
    """The reconstruction stage draws its fabricated parts, the tolerance stage its Monte Carlo, from the budget:
    a new budget under the same file name must not reuse their finished results."""
    from doefab.pipeline.scene import load_scene

    scene = tmp_path / "s.toml"
    scene.write_text('task = "hdr"\n[tolerance]\nbudget = "b.toml"\n')
    (tmp_path / "b.toml").write_text("[overlay]\nshift_sigma_um = 0.5\n")
    first = {n: stagerun.stage_hash(load_scene(scene), n, {}, False) for n in ("reconstruction", "tolerance", "holder")}
    (tmp_path / "b.toml").write_text("[overlay]\nshift_sigma_um = 1.5\n")
    second = {n: stagerun.stage_hash(load_scene(scene), n, {}, False) for n in first}
    assert first["reconstruction"] != second["reconstruction"] and first["tolerance"] != second["tolerance"]
    assert first["holder"] == second["holder"]


def test_the_reconstruction_stage_resumes_each_networks_training(tmp_path, monkeypatch):
    """An interrupted training run of the scene's networks continues from its checkpoint (the others start)."""
    import doefab.reconstruction.train as train_mod
    import doefab.tolerance.conditions as cond_mod

    got = []

    class Stop(Exception):
        pass

    def fake_train(task, variant, minutes, out_dir, **kw):
        got.append((variant, kw["resume"]))
        if len(got) == 3:
            raise Stop
        return {"training": {"warm_start": None}}

    monkeypatch.setattr(train_mod, "train", fake_train)
    monkeypatch.setattr(cond_mod, "for_splits", lambda *a, **k: {})
    (tmp_path / "design").mkdir()
    out = tmp_path / "reconstruction"
    (out / "run_coded_only").mkdir(parents=True)
    (out / "run_coded_only" / "checkpoint.pt").write_bytes(b"x")
    scene = SimpleNamespace(reconstruction={"weights": "train", "minutes": 1}, task="hdr", tolerance=None)
    with pytest.raises(Stop):
        stages.stage_reconstruction(scene, SimpleNamespace(reuse=False, sensor=None, settings={"design_task": "streak"}),
                                    out, False)
    assert got == [("proposed", False), ("coded_only", True), ("uncoded_only", False)]
