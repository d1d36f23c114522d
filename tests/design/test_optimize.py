import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError
from doefab.tasks import get_task


def _initial_metric(cam, params):
    task = get_task("streak", **params)
    h = task.init_height(cam, np.random.default_rng(0))
    plan = doefab.PSFPlan(cam, task.wavelengths(cam), task.depths(cam), task.kernel_size, halves=("coded",))
    with torch.no_grad():
        return task.metric(plan(h).coded, cam)["value"], float(task.loss(plan(h).coded, cam))


@pytest.mark.parametrize("optimizer", ["adam", "lbfgs"])
def test_short_optimisation_lowers_loss_and_raises_metric(tiny_camera, tiny_streak, optimizer):
    m0, l0 = _initial_metric(tiny_camera, tiny_streak)
    d = doefab.optimize("streak", iterations=25, optimizer=optimizer, camera=tiny_camera, progress=False,
                        task_params=tiny_streak, qat_fraction=0.0, lr=0.05)
    losses = [row[2] for row in d.history]
    assert min(losses) < l0 - 0.05
    assert d.metrics["continuous"] > m0 + 0.05
    assert d.levels.dtype == np.uint8 and d.levels.max() <= 15


def test_same_seed_same_design(tiny_camera, tiny_streak):
    a = doefab.optimize("streak", iterations=5, camera=tiny_camera, progress=False, task_params=tiny_streak, seed=3)
    b = doefab.optimize("streak", iterations=5, camera=tiny_camera, progress=False, task_params=tiny_streak, seed=3)
    assert np.array_equal(a.levels, b.levels)
    assert [r[2] for r in a.history] == [r[2] for r in b.history]


def test_resume_after_interruption_equals_uninterrupted(tiny_camera, tiny_streak, tmp_path, monkeypatch):
    kw = dict(iterations=8, camera=tiny_camera, progress=False, task_params=tiny_streak, checkpoint_every=3,
              batch=0, lr=0.05)
    full = doefab.optimize("streak", out_dir=tmp_path / "a", **kw)
    real = doefab.PSFPlan.half_psf
    calls = {"n": 0}

    def dying(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 6:  # in the middle of step 5 (one call per step, plus metric evaluations)
            raise KeyboardInterrupt
        return real(self, *a, **k)

    monkeypatch.setattr(doefab.PSFPlan, "half_psf", dying)
    with pytest.raises(KeyboardInterrupt):
        doefab.optimize("streak", out_dir=tmp_path / "b", **kw)
    monkeypatch.setattr(doefab.PSFPlan, "half_psf", real)
    assert (tmp_path / "b" / "checkpoint.pt").is_file()
    resumed = doefab.optimize("streak", out_dir=tmp_path / "b", resume=True, **kw)
    assert np.array_equal(full.levels, resumed.levels)
    assert [r[2] for r in full.history] == [r[2] for r in resumed.history]


def test_nonfinite_loss_stops_and_keeps_checkpoint(tiny_camera, tiny_streak, tmp_path, monkeypatch):
    task = get_task("streak", **tiny_streak)
    real = type(task).loss
    calls = {"n": 0}

    def bad_loss(self, *a, **k):
        calls["n"] += 1
        out = real(self, *a, **k)
        return out * float("nan") if calls["n"] >= 4 else out

    monkeypatch.setattr(type(task), "loss", bad_loss)
    with pytest.raises(DoefabError, match="loss became nan at step 3.*last good checkpoint"):
        doefab.optimize(task, iterations=10, camera=tiny_camera, progress=False, out_dir=tmp_path, checkpoint_every=2)
    assert (tmp_path / "checkpoint.pt").is_file()
    calls["n"] = 0
    with pytest.raises(DoefabError, match="loss became nan"):  # nlopt must not swallow it either
        doefab.optimize(task, iterations=10, optimizer="lbfgs", camera=tiny_camera, progress=False)


def test_resume_refuses_other_settings_and_corrupt_checkpoint(tiny_camera, tiny_streak, tmp_path):
    kw = dict(camera=tiny_camera, progress=False, task_params=tiny_streak, out_dir=tmp_path, checkpoint_every=2)
    doefab.optimize("streak", iterations=2, **kw)
    with pytest.raises(DoefabError, match="other settings"):
        doefab.optimize("streak", iterations=2, resume=True, seed=9, **kw)
    (tmp_path / "checkpoint.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(DoefabError, match="corrupt"):
        doefab.optimize("streak", iterations=2, resume=True, **kw)


def test_a_fresh_run_never_removes_or_replaces_a_users_checkpoint_or_history(tiny_camera, tiny_streak, tmp_path):
    """out_dir may be a folder of the user's: a checkpoint.pt or history.csv there that doefab did not write is
    refused, and stays as it was; doefab's own from an earlier run is cleared."""
    import torch

    kw = dict(camera=tiny_camera, progress=False, task_params=tiny_streak, out_dir=tmp_path, checkpoint_every=2)
    torch.save({"weights": torch.zeros(2)}, tmp_path / "theirs.pt")  # the user's own torch file, no doefab config
    mine = {"checkpoint.pt": (tmp_path / "theirs.pt").read_bytes(), "history.csv": b"epoch,loss\n1,0.5\n"}
    for name, data in mine.items():
        for f in mine:
            (tmp_path / f).unlink(missing_ok=True)
        (tmp_path / name).write_bytes(data)
        with pytest.raises(DoefabError, match=f"{name}: not written by doefab, so never removed or replaced"):
            doefab.optimize("streak", iterations=2, **kw)
        assert (tmp_path / name).read_bytes() == data
    (tmp_path / "history.csv").unlink()
    doefab.optimize("streak", iterations=2, **kw)  # writes doefab's own checkpoint.pt
    (tmp_path / "history.csv").write_bytes(b"step,wall_time_s,loss,metric\n")  # an earlier run's history
    doefab.optimize("streak", iterations=2, **kw)  # both doefab's: cleared, no refusal
    assert not (tmp_path / "history.csv").exists() and (tmp_path / "checkpoint.pt").is_file()


def test_bad_optimizer_inputs(tiny_camera):
    with pytest.raises(DoefabError, match="unknown task"):
        doefab.optimize("wobble", iterations=2, camera=tiny_camera)
    with pytest.raises(DoefabError, match="unknown optimizer"):
        doefab.optimize("streak", iterations=2, optimizer="sgd", camera=tiny_camera)
    with pytest.raises(DoefabError, match="iterations"):
        doefab.optimize("streak", iterations=0, camera=tiny_camera)
    with pytest.raises(DoefabError, match="unknown design settings"):
        doefab.optimize("streak", iterations=1, camera=tiny_camera, learning_rate=3)


def test_stratified_batch_sees_every_depth(tiny_camera):
    d = doefab.optimize("half-ring", iterations=2, camera=tiny_camera, progress=False, batch=-1,
                        task_params={"z_step": 1.0})
    assert len(d.history) == 2 and len(d.depths) == 5


def test_a_resume_may_raise_the_iterations_not_lower_them(tiny_camera, tiny_streak, tmp_path):
    """Fewer iterations on resume would skip the quantization-aware steps the run was set up for."""
    kw = dict(camera=tiny_camera, progress=False, task_params=tiny_streak, out_dir=tmp_path, checkpoint_every=1)
    doefab.optimize("streak", iterations=4, **kw)
    with pytest.raises(DoefabError, match="a resume may raise --iterations, not lower it \\(to 3\\)"):
        doefab.optimize("streak", iterations=3, resume=True, **kw)
    assert doefab.optimize("streak", iterations=5, resume=True, **kw).levels is not None
