"""The training bar a user watches: the validation metric shows as a dash until the first validation (never
"nan"), then its value; the bar counts the time budget's seconds without a rate in "s/s"."""

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
