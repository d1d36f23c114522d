"""``design.pace.design_time``: the run time of a design from a few of its own steps. The parts it adds are those
a run spends (counted against a real run's metric evaluations, and against hand arithmetic on a scripted clock);
``doefab doctor`` times exactly the design ``doefab run`` optimises."""

import importlib

import pytest

import doefab
from doefab.errors import DoefabError

opt = importlib.import_module("doefab.design.optimize")  # the module (the package re-exports its function)
pace = importlib.import_module("doefab.design.pace")

CAM = dict(doe_pixels=256, doe_pitch=33.75e-6)


@pytest.mark.parametrize("iterations, every", [(45, 20), (45, 7), (40, 20), (1, 20)])
def test_the_full_metrics_counted_are_those_a_run_evaluates(monkeypatch, iterations, every):
    calls = []
    real = opt.DesignRun.full_metric

    def counted(self, quantized):
        calls.append(quantized)
        return real(self, quantized)

    monkeypatch.setattr(opt.DesignRun, "full_metric", counted)
    doefab.optimize("streak", iterations=iterations, camera=doefab.Camera(**CAM), progress=False, eval_every=every)
    ran = len(calls)
    calls.clear()
    t = pace.design_time("streak", iterations=iterations, camera=doefab.Camera(**CAM), eval_every=every)
    assert t["evaluations"] == ran and t["iterations"] == iterations
    assert len(calls) == 1  # design_time itself evaluates the metric once, to time it


class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


@pytest.mark.parametrize("steps, timed, step_s", [(None, [1.0, 5.0, 1.2], 1.2), (2, [1.0, 5.0], 1.0)])
def test_the_estimate_adds_set_up_steps_metrics_and_the_full_grid_finish(monkeypatch, steps, timed, step_s):
    """A scripted clock: the first step (with the set-up) 6 s, then the timed steps — by default three, 1.0, 5.0 (a
    stray slow one) and 1.2 s, median 1.2; two, 1.0 and 5.0, the lower middle 1.0 —, a full metric 3 s; 50 steps
    with the metric every 20 (steps 0, 20, 40 and the last, 49: 4 of them) and a grid coarsened 2× (the finish: two
    metrics on 4× the pixels). By hand: (6 − step) + 50·step + 4·3 + 2·4·3 = 100.8 s for 1.2, 91 s for 1.0."""
    clock = _Clock()
    durations = iter([6.0, *timed])

    class FakeRun:
        cfg = type("Cfg", (), {"iterations": 50, "eval_every": 20, "sampling": 2})()
        dcam = type("Cam", (), {"doe_pixels": 400})()
        dev = "cpu"

        def one_step(self, step):
            clock.now += next(durations)

        def full_metric(self, quantized):
            clock.now += 3.0

    monkeypatch.setattr(pace.time, "perf_counter", clock)
    monkeypatch.setattr(opt, "prepare_run", lambda *a, **k: FakeRun())
    t = pace.design_time("streak", **({} if steps is None else {"steps": steps}))
    assert t["seconds"] == pytest.approx({1.2: 100.8, 1.0: 91.0}[step_s])
    assert (t["evaluations"], t["grid_px"]) == (4, 400)
    assert (t["step_s"], t["metric_s"], t["setup_s"]) == pytest.approx((step_s, 3.0, 6.0 - step_s))


def test_steps_outside_their_range_are_one_clear_error():
    with pytest.raises(DoefabError, match="steps must be"):
        pace.design_time("streak", steps=0, camera=doefab.Camera(**CAM))


def test_one_step_takes_adams_first_step_on_the_gradient():
    """Adam's first step moves each parameter by lr·g/(|g| + ε) against its gradient g (bias-corrected moments:
    m̂ = g, v̂ = g²), whatever g's size."""
    run = opt.prepare_run("streak", iterations=3, camera=doefab.Camera(**CAM))
    before = run.theta.detach().clone()
    run.one_step(0)
    g = run.theta.grad
    assert float(g.abs().max()) > 0
    step = run.theta.detach() - before
    assert step.numpy() == pytest.approx((-run.cfg.lr * g / (g.abs() + 1e-8)).numpy(), abs=1e-6)


def test_one_step_of_nlopt_is_one_fresh_gradient_and_no_move():
    """An nlopt evaluation: the objective's gradient over every pair at θ (not added to the last one), θ unmoved."""
    import torch

    run = opt.prepare_run("streak", iterations=3, optimizer="lbfgs", camera=doefab.Camera(**CAM))
    before = run.theta.detach().clone()
    run.one_step(0)
    run.one_step(1)
    (expected,) = torch.autograd.grad(run.objective(1), run.theta)
    assert bool((run.theta.detach() == before).all())
    assert run.theta.grad.numpy() == pytest.approx(expected.numpy(), rel=1e-5, abs=1e-9)


def test_a_design_nlopt_would_refuse_is_refused_before_it_is_timed(monkeypatch):
    """``prepare_run`` refuses what the nlopt driver would (``check_nlopt_size``): here with the limit lowered below
    the small test grid's coded pixels, so that no large grid is built."""
    nloptrun = importlib.import_module("doefab.design.nloptrun")
    monkeypatch.setattr(nloptrun, "NLOPT_MAX_VARIABLES", 100)
    with monkeypatch.context() as m:
        m.setattr(opt.DesignRun, "one_step", lambda self, step: pytest.fail("a refused design was stepped"))
        with pytest.raises(DoefabError, match="nlopt's optimisers take at most 100 variables"):
            pace.design_time("streak", iterations=5, optimizer="lbfgs", camera=doefab.Camera(**CAM))
    assert pace.design_time("streak", iterations=5, camera=doefab.Camera(**CAM))["iterations"] == 5  # Adam: no limit
