"""The training loop a user runs: the bar's validation metric shows as a dash until the first validation (never
"nan"), then its value; the bar counts the steps when they are counted, else the time budget's seconds, without a
rate in "s/s". With counted steps the learning rate follows the steps alone (a run repeats bit for bit however slow
its validation); a finished run resumed adds no row; a checkpoint write a kill left half done is cleared."""

import math
import time

import torch

from doefab.reconstruction.loop import run_loop


def test_the_bar_shows_no_nan_before_the_first_validation_and_its_value_after(tmp_path, capsys):
    w = torch.nn.Parameter(torch.zeros(()))
    opt = torch.optim.SGD([w], lr=0.1)

    def step(i):
        opt.zero_grad()
        loss = (w - 1.0) ** 2
        loss.backward()
        opt.step()
        return float(loss.detach())

    run_loop(tmp_path, {"case": "bar"}, 1.0, step, lambda: 0.125, {"w": opt}, [(opt, 0.1)], metric="psnr",
             val_every=3, max_steps=4, desc="train test")
    err = capsys.readouterr().err
    assert "psnr=–" in err  # steps 1 and 2: no validation yet
    assert "psnr=0.125" in err  # from step 3
    assert "nan" not in err and "s/s" not in err


def test_a_validation_that_returns_nan_shows_as_nan(tmp_path, capsys):
    """A diverged network's metric is shown as it is, not as the dash of "not validated yet"."""
    w = torch.nn.Parameter(torch.zeros(()))
    opt = torch.optim.SGD([w], lr=0.0)
    run_loop(tmp_path, {"case": "nan"}, 1.0, lambda i: 1.0, lambda: float("nan"), {"w": opt}, [(opt, 0.0)],
             metric="mae", val_every=1, max_steps=2, desc="train test")
    err = capsys.readouterr().err
    assert "mae=nan" in err and "mae=–" not in err


def _quadratic():
    w = torch.nn.Parameter(torch.zeros(()))
    opt = torch.optim.SGD([w], lr=0.1)
    rates = []

    def step(i):
        rates.append(opt.param_groups[0]["lr"])
        opt.zero_grad()
        loss = (w - 1.0) ** 2
        loss.backward()
        opt.step()
        return float(loss.detach())

    return w, opt, rates, step


def test_with_counted_steps_the_rate_follows_the_steps_alone(tmp_path):
    """A slow first validation (as fine-tuning makes) must not move the rates: step i's is the cosine's at i / N,
    0.5 (1 + cos(π i / N)) above the floor, written out here; the same weights twice."""
    from doefab.reconstruction.loop import LR_FLOOR

    finals = []
    for run in ("a", "b"):
        w, opt, rates, step = _quadratic()

        def slow_validation():
            time.sleep(0.05)
            return 0.0

        run_loop(tmp_path / run, {"case": "rate"}, 0.05, step, slow_validation, {"w": opt}, [(opt, 0.1)],
                 val_every=100, max_steps=5, progress=False, validate_first=True)
        want = [0.1 * (LR_FLOOR + (1 - LR_FLOOR) * 0.5 * (1 + math.cos(math.pi * i / 5))) for i in range(5)]
        assert rates == want
        finals.append(float(w.detach()))
    assert finals[0] == finals[1]


def test_the_bar_counts_steps_when_they_are_counted(tmp_path, capsys):
    w, opt, rates, step = _quadratic()
    run_loop(tmp_path, {"case": "steps"}, 30.0, step, lambda: 0.5, {"w": opt}, [(opt, 0.1)], val_every=2,
             max_steps=4, desc="train test")
    err = capsys.readouterr().err
    assert "4/4" in err and "/1800" not in err  # the steps, not the 30 min budget's seconds (a rate may read 1800)


def test_a_finished_run_resumed_adds_no_row_and_a_half_written_checkpoint_is_cleared(tmp_path):
    w, opt, rates, step = _quadratic()
    args = (tmp_path, {"case": "again"}, 1.0, step, lambda: 0.25, {"w": opt}, [(opt, 0.1)])
    steps, history, _ = run_loop(*args, val_every=2, max_steps=4, progress=False)
    csv = (tmp_path / "history.csv").read_text()
    stale = tmp_path / ".checkpoint.pt.abc123"
    stale.write_bytes(b"half a checkpoint")
    stale_rows = tmp_path / ".history.csv.k9"
    stale_rows.write_text("step,loss\n")
    again, history2, _ = run_loop(*args, val_every=2, max_steps=4, progress=False, resume=True)
    assert again == steps == 4 and len(history2) == len(history) and history2[-1] == history[-1]
    assert (tmp_path / "history.csv").read_text() == csv and not stale.exists() and not stale_rows.exists()


def test_a_resume_with_other_settings_names_each_one_that_differs(tmp_path):
    import pytest

    from doefab.errors import DoefabError

    w, opt, rates, step = _quadratic()
    config = {"batch": 4, "lr": 1e-3, "arch": {"width": 16, "planes": 17}}
    run_loop(tmp_path, config, 1.0, step, lambda: 0.0, {"w": opt}, [(opt, 0.1)], max_steps=2, val_every=1,
             progress=False)
    other = {"batch": 2, "lr": 1e-3, "arch": {"width": 8, "planes": 17}}
    with pytest.raises(DoefabError, match=r"other settings \(arch\.width: 16 there, 8 now; batch: 4 there, 2 now\)"):
        run_loop(tmp_path, other, 1.0, step, lambda: 0.0, {"w": opt}, [(opt, 0.1)], max_steps=4, val_every=1,
                 progress=False, resume=True)


def test_a_run_killed_after_its_last_step_but_before_its_final_validation_gets_it_on_resume(tmp_path):
    """The checkpoint saved at the last step (step 4, val_every 2) is not a finished run: killed before the final
    validation, a resume adds that row (only a run saved as finished is returned as it is)."""
    import pytest

    w, opt, rates, step = _quadratic()
    calls = []

    def validate():
        calls.append(1)
        if len(calls) == 3:  # steps 2 and 4, then the final validation: killed there
            raise KeyboardInterrupt
        return 0.5

    args = (tmp_path, {"case": "killed"}, 1.0, step, validate, {"w": opt}, [(opt, 0.1)])
    with pytest.raises(KeyboardInterrupt):
        run_loop(*args, val_every=2, max_steps=4, progress=False)
    saved = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    assert saved["step"] == 4 and not saved["finished"] and len(saved["history"]) == 4
    steps, history, _ = run_loop(*args, val_every=2, max_steps=4, progress=False, resume=True)
    assert steps == 4 and len(history) == 5 and history[-1][3] == 0.5
    assert torch.load(tmp_path / "checkpoint.pt", weights_only=True)["finished"]


def test_a_fresh_run_clears_an_earlier_runs_checkpoint_before_its_first_step(tmp_path):
    """A fresh run (no resume) in a folder that holds an earlier run's checkpoint and history: interrupted at its
    first step, nothing of the earlier run is left for a later --resume to continue (fine-tuning and training take
    this loop; ``doefab design`` clears the same way, ``design.checkpoint.clear_checkpoint``)."""
    import pytest

    w, opt, rates, step = _quadratic()
    run_loop(tmp_path, {"case": "earlier"}, 1.0, step, lambda: 0.0, {"w": opt}, [(opt, 0.1)], max_steps=2,
             val_every=1, progress=False)
    (tmp_path / "levels.npy").write_bytes(b"earlier run")
    assert {"checkpoint.pt", "history.csv"} <= {p.name for p in tmp_path.iterdir()}

    def interrupted(i):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_loop(tmp_path, {"case": "fresh"}, 1.0, interrupted, lambda: 0.0, {"w": opt}, [(opt, 0.1)], max_steps=2,
                 progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["levels.npy"]
