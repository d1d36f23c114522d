"""The design's optimisation driven by nlopt (L-BFGS, MMA) on torch's gradients: θ's coded pixels as nlopt's
variables, nlopt's early stops restarted from the best point while the evaluation budget lasts."""

from __future__ import annotations

import numpy as np
import torch

from doefab.errors import DoefabError

__all__ = ["run_nlopt", "check_nlopt_size", "nlopt_takes_variables", "NLOPT_MAX_VARIABLES"]

NLOPT_MAX_VARIABLES = 2_000_000  # nlopt 2.x's L-BFGS fails (runtime_error) from about 2.1 M variables


def run_nlopt(name, theta, objective, record, step0, iterations, qat_start, mask) -> str | None:
    """nlopt driven by torch gradients, run to its evaluation budget.

    The continuous and the quantization-aware stages are separate nlopt runs (the straight-through objective
    is a different function), each keeping its best point. nlopt ends early when its line search cannot
    progress (e.g. ``RoundoffLimited`` on these wrapped-phase objectives); doefab then restarts it from the
    best point (a fresh L-BFGS memory / MMA model) while the budget lasts. A first attempt that does not
    lower the loss at all is an error; a later restart without progress ends the run with a stated reason,
    which is returned (None when the whole budget ran). Only the coded pixels (``mask``) are variables.
    """
    check_nlopt_size(name, mask)
    idx = torch.nonzero(mask.flatten() > 0).flatten().to(theta.device)
    run = _NloptRun(name, theta, idx, objective, record, step0, iterations)
    run.stage(min(qat_start, iterations), "continuous stage")
    if qat_start < iterations:  # a continuous stage that gave up early leaves its budget unused; QAT still runs
        run.step = max(run.step, qat_start)
        run.stage(iterations, "quantization-aware stage")
    return "; ".join(run.reasons) or None


def nlopt_takes_variables(n: int) -> bool:
    """Whether nlopt's optimisers take ``n`` variables (at most ``NLOPT_MAX_VARIABLES``)."""
    return n <= NLOPT_MAX_VARIABLES


def check_nlopt_size(name: str, mask) -> None:
    """One error, before any work, where the variables ``mask`` marks (a pixel design's coded pixels, a radial
    profile's knots) are more than nlopt's optimisers take (``nlopt_takes_variables``)."""
    n = int((mask > 0).sum())
    if not nlopt_takes_variables(n):
        raise DoefabError(f"{name}: this design has {n:,} coded DOE pixels but nlopt's optimisers take at most "
                          f"{NLOPT_MAX_VARIABLES:,} variables: use --sampling 2 (or more) or --optimizer adam")


class _NloptRun:
    """The state of one nlopt-driven design run: θ's coded pixels ``idx`` as nlopt's variables, the evaluation
    counter ``step`` (shared by the stages and restarts), and the reasons a stage ended early."""

    def __init__(self, name, theta, idx, objective, record, step0: int, iterations: int):
        import nlopt

        self.nlopt, self.name, self.theta, self.idx = nlopt, name, theta, idx
        self.objective, self.record, self.step0, self.iterations = objective, record, step0, iterations
        self.flat = theta.data.view(-1)
        self.algo = {"lbfgs": nlopt.LD_LBFGS, "mma": nlopt.LD_MMA}[name]
        self.label = {"lbfgs": "L-BFGS", "mma": "MMA"}[name]
        self.step, self.reasons = step0, []

    def _evaluate(self, x, grad, end: int, best: dict, stop: list) -> float:
        """nlopt's objective: θ set to ``x``, the loss and (into ``grad``) its gradient; the best point kept."""
        step = self.step
        if step >= end:  # nlopt may ask for one more than maxeval: the budget is ours to keep
            raise self.nlopt.ForcedStop
        theta, idx = self.theta, self.idx
        try:
            with torch.no_grad():
                self.flat[idx] = torch.from_numpy(np.array(x, copy=True)).to(theta.device, theta.dtype)
            theta.grad = None
            loss = self.objective(min(step, self.iterations - 1))
            if torch.isfinite(loss):
                loss.backward()
            if grad.size > 0:
                grad[:] = (theta.grad.detach().reshape(-1)[idx].double().cpu().numpy() if theta.grad is not None
                           else 0.0)
            value = float(loss.detach())
            self.record(step, value)
        except (DoefabError, KeyboardInterrupt) as exc:  # nlopt would swallow it: keep it and stop
            stop.append(exc)
            raise self.nlopt.ForcedStop from None
        if best["first"] is None:
            best["first"] = value
        if value < best["loss"]:
            best["loss"], best["x"] = value, np.array(x, copy=True)
        self.step += 1
        return value

    def attempt(self, end: int) -> tuple[bool, str]:
        """One nlopt run from the current θ up to evaluation ``end``; returns (lowered the loss, outcome)."""
        nlopt = self.nlopt
        x0 = self.flat[self.idx].double().cpu().numpy().copy()
        best = {"loss": float("inf"), "x": x0, "first": None}
        stop: list = []
        opt = nlopt.opt(self.algo, int(self.idx.numel()))
        opt.set_min_objective(lambda x, grad: self._evaluate(x, grad, end, best, stop))
        opt.set_maxeval(max(end - self.step, 1))
        if self.name == "mma":  # MMA needs bounds; θ is periodic, so a wide box is no constraint in practice
            opt.set_lower_bounds(x0 - 1e3)
            opt.set_upper_bounds(x0 + 1e3)
        outcome = "budget reached"
        try:
            opt.optimize(x0)
            if self.step < end:
                outcome = f"returned code {opt.last_optimize_result()}"
        except nlopt.ForcedStop:
            if stop:
                raise stop[0] from None
        except Exception as exc:  # noqa: BLE001 - nlopt's own errors (RoundoffLimited, generic failure)
            outcome = f"nlopt {exc.__class__.__name__}" + (f" ({exc})" if str(exc) else "")
        with torch.no_grad():
            self.flat[self.idx] = torch.from_numpy(best["x"]).to(self.theta.device, self.theta.dtype)
        first = best["first"]
        lowered = first is not None and best["loss"] < first - 1e-7 * max(1.0, abs(first))
        return lowered, outcome

    def stage(self, end: int, stage: str) -> bool:
        """Attempts, each restarted from the best point, until evaluation ``end`` or one that lowers nothing."""
        tries = 0
        while self.step < end:
            before = self.step
            lowered, outcome = self.attempt(end)
            tries += 1
            if self.step >= end:
                return True
            if not lowered:
                if tries == 1 and self.step - before <= 3 and before == self.step0:
                    raise DoefabError(f"{self.label} stopped after {self.step - before} evaluations of "
                                      f"{self.iterations} without lowering the loss ({outcome}): no design was "
                                      f"made; use --optimizer adam")
                self.reasons.append(f"{self.label} ({stage}) stopped at evaluation {self.step} of {self.iterations}: "
                                    f"{outcome}, and a restart from the best point did not lower the loss")
                return False
        return True
