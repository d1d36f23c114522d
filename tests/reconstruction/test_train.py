"""The wall-time learning-rate schedule of ``doefab train``."""

import math

import pytest
import torch

from doefab.errors import DoefabError
from doefab.reconstruction.loop import LR_FLOOR, lr_factor
from doefab.reconstruction.train import train


def test_cosine_factor_is_half_a_cosine_to_the_floor():
    assert lr_factor("cosine", 0.0) == pytest.approx(1.0)
    assert lr_factor("cosine", 0.5) == pytest.approx((1 + LR_FLOOR) / 2)
    assert lr_factor("cosine", 0.25) == pytest.approx(LR_FLOOR + (1 - LR_FLOOR) * (1 + math.cos(math.pi / 4)) / 2)
    assert lr_factor("cosine", 1.0) == pytest.approx(LR_FLOOR)
    assert lr_factor("cosine", 3.0) == pytest.approx(LR_FLOOR)  # a resumed run past its budget
    assert lr_factor("constant", 0.9) == 1.0
    with pytest.raises(DoefabError, match="unknown learning-rate schedule"):
        lr_factor("step", 0.5)


def test_training_anneals_over_its_wall_time_budget(tmp_path):
    meta = train("hdr", "proposed", minutes=0.2, out_dir=tmp_path / "run", weights_dir=tmp_path / "w", crop=64,
                 val_images=1, val_every=1000, progress=False,
                 arch={"features": 1, "width": 4, "highlight_iters": 1, "bound_iters": 0},  # fast steps
                 lr=1e-3)
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    last_lr = state["optimizer"]["param_groups"][0]["lr"]
    assert meta["training"]["schedule"] == "cosine" and meta["training"]["steps"] >= 2
    assert last_lr < 0.5e-3  # the last step ran in the second half of the budget, well below the start rate
    assert last_lr >= LR_FLOOR * 1e-3 * (1 - 1e-9)
    # a training checkpoint holds the network, its optimiser and the loop's state, nothing of a DOE
    assert "theta" not in state and {"model", "optimizer", "step", "history"} <= set(state)


@pytest.mark.parametrize("flag, want", [([], "honest"), (["--clean"], "clean")])
def test_evaluate_at_the_command_line_is_honest_unless_asked_for_the_clean_captures(tmp_path, monkeypatch, flag,
                                                                                     want):
    """``doefab evaluate`` renders through fabricated parts with crosstalk by default; ``--clean`` is the
    nominal model's own captures (the conditions handed to ``evaluate`` and recorded in metrics.json)."""
    import json

    import doefab.tolerance.conditions as cond
    from doefab.cli import main

    monkeypatch.setattr(cond, "_parts", lambda task, d, split, n, budget, progress: [])  # no PSFs computed here
    rc = main(["evaluate", "--task", "hdr", "--images", "1", "--size", "64", "--variants", "uncoded_only",
               "--split", "val", "--out", str(tmp_path / "ev"), *flag])
    assert rc == 0
    rec = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert rec["conditions"]["name"] == want and rec["split"] == "val"
    assert rec["conditions"].get("crosstalk", False) is (want == "honest")


def test_training_crop_defaults_to_the_tasks(tmp_path):
    """Depth trains on 128-pixel crops (the cost volume of a 95-pixel PSF needs room), the others on 96."""
    from doefab.reconstruction.specs import get_spec

    assert get_spec("depth").crop == 128 and get_spec("hdr").crop == 96
    meta = train("depth", "coded_only", minutes=5, out_dir=tmp_path / "run", weights_dir=tmp_path / "w",
                 val_images=1, val_every=1000, progress=False, arch={"width": 4, "cost_volume": False},
                 max_steps=1)
    assert meta["training"]["crop_px"] == 128 and meta["validation"]["crop_px"] == 128


def test_a_training_record_names_its_threads_device_code_and_libraries_and_the_threads_are_restored(tmp_path):
    """The weights' last bits follow torch's thread count: the record names the count the run trained on (at
    most 2), and the caller's count is back afterwards."""
    from doefab.reconstruction.provenance import library_versions

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(3)
        meta = train("hdr", "uncoded_only", minutes=1, out_dir=tmp_path / "run", weights_dir=tmp_path / "w",
                     crop=64, val_images=1, val_every=1000, progress=False, max_steps=1,
                     arch={"features": 1, "width": 4, "highlight_iters": 1, "bound_iters": 0})
        assert torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(before)
    t = meta["training"]
    assert t["threads"] == 2 and t["device"] == "cpu" and t["versions"]["torch"] == torch.__version__
    assert set(t["versions"]) == set(library_versions()) and t["code"].startswith(("git ", "doefab "))
    assert "stopped" not in t  # its one step ran


def test_a_run_of_counted_steps_that_the_clock_stops_says_so(tmp_path):
    meta = train("hdr", "uncoded_only", minutes=0.01, out_dir=tmp_path / "run", weights_dir=tmp_path / "w",
                 crop=64, val_images=1, val_every=1000, progress=False, max_steps=100000,
                 arch={"features": 1, "width": 4, "highlight_iters": 1, "bound_iters": 0})
    steps = meta["training"]["steps"]
    assert steps < 100000 and f"ended the run at step {steps} of 100000" in meta["training"]["stopped"]


@pytest.mark.parametrize("flag, want", [([], None), (["--crop", "160"], 160)])
def test_train_at_the_command_line_leaves_the_crop_to_the_task_unless_given(tmp_path, monkeypatch, flag, want):
    import doefab.reconstruction.train as train_mod
    from doefab.cli import main

    got = {}

    def fake(*a, **k):
        got.update(k)
        raise SystemExit(0)  # stop before any training

    monkeypatch.setattr(train_mod, "train", fake)
    with pytest.raises(SystemExit):
        main(["train", "--task", "depth", "--variant", "coded_only", "--clean", "--steps", "1",
              "--out", str(tmp_path / "t"), *flag])
    assert got["crop"] == want  # None: train() takes the task's crop (128 for depth)


@pytest.mark.parametrize("task", ["hdr", "hyperspectral"])
def test_a_run_for_the_default_sensor_keeps_its_old_record(task, tmp_path, monkeypatch):
    """The run's config (what a resumed run must match) names a sensor only when it is not the default one, so
    checkpoints made before sensors existed resume; another noise is named."""
    import doefab.reconstruction.train as train_mod
    from doefab.imaging.sensor import Sensor

    configs = []

    class Stop(Exception):
        pass

    def spy(out, config, *args, **kw):
        configs.append(config)
        raise Stop

    monkeypatch.setattr(train_mod, "run_loop", spy)
    for sensor in (None, Sensor(), Sensor(read_noise_e=5.0)):
        with pytest.raises(Stop):
            train(task, "uncoded_only", minutes=1, out_dir=tmp_path / "run", weights_dir=tmp_path / "w", crop=64,
                  val_images=1, progress=False, arch={"features": 1, "width": 4}, sensor=sensor)
    assert "sensor" not in configs[0] and configs[0] == configs[1]
    assert configs[2]["sensor"]["read_noise_e"] == 5.0
