"""Optimiser runs (``design.optimize``, ``design.nloptrun``): L-BFGS uses its whole budget, nlopt without
progress is an error, a run resumes with more iterations."""

import pytest
import torch

import doefab
from doefab.errors import DoefabError


def test_lbfgs_runs_its_whole_budget(tiny_camera, tiny_streak):
    d = doefab.optimize("streak", iterations=20, optimizer="lbfgs", camera=tiny_camera, progress=False,
                        task_params=tiny_streak, qat_fraction=0.25)
    assert d.extra["evaluations"] == 20 and "stop_reason" not in d.extra
    assert [r[0] for r in d.history] == list(range(20))
    assert min(r[2] for r in d.history) < d.history[0][2] - 0.05


def test_nlopt_without_progress_is_an_error_not_a_result():
    from doefab.design.nloptrun import run_nlopt

    theta = torch.zeros(4, 4, requires_grad=True)
    rec = []
    with pytest.raises(DoefabError, match="without lowering the loss"):
        run_nlopt("lbfgs", theta, lambda step: (theta * 0).sum() + 1.0, lambda s, v: rec.append(v), 0, 10, 10,
                  torch.ones(4, 4))
    assert len(rec) < 10


def test_nlopt_refuses_more_variables_than_it_can_take():
    from doefab.design.nloptrun import run_nlopt

    theta = torch.zeros(1500, 1500, requires_grad=True)
    with pytest.raises(DoefabError, match="--sampling 2"):
        run_nlopt("lbfgs", theta, None, None, 0, 10, 10, torch.ones(1500, 1500))


def test_resume_may_extend_iterations(tiny_camera, tiny_streak, tmp_path):
    kw = dict(camera=tiny_camera, progress=False, task_params=tiny_streak, checkpoint_every=2, batch=0, lr=0.05,
              qat_fraction=0.0)
    doefab.optimize("streak", iterations=4, out_dir=tmp_path, **kw)
    d = doefab.optimize("streak", iterations=7, out_dir=tmp_path, resume=True, **kw)
    assert [r[0] for r in d.history] == list(range(7))
