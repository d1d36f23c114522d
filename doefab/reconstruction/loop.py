"""One training loop for every network doefab trains (``train``, and ``endtoend`` with its DOE): a wall-time
budget, a learning rate that follows a cosine over that budget, validation every few steps, checkpoints that
resume exactly, ``history.csv`` and a progress bar with the loss and the validation metric.

A fixed-minutes run cannot know its step count in advance, and a network trained for minutes gains most from
annealing at the end: ``schedule="cosine"`` decays every optimiser's rate to ``LR_FLOOR`` of its start over
the budget (``"constant"`` keeps it); a resumed run continues the schedule from the checkpoint's elapsed time,
and a larger budget on resume stretches it (the rate rises again). Checkpoints hold the modules' and
optimisers' states, any extra tensors (the end-to-end DOE's parameters), the step, the elapsed time, the
history and torch's random state; they are written atomically and loaded with ``weights_only=True``.
"""

from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.io import atomic_write_text

__all__ = ["run_loop", "lr_factor", "SCHEDULES", "LR_FLOOR", "training_threads", "torch_threads"]

SCHEDULES = ("cosine", "constant")
LR_FLOOR = 0.05


@contextlib.contextmanager
def torch_threads(n: int):
    """torch on ``n`` thread(s) inside the block, the caller's thread count restored after."""
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def training_threads(fn):
    """Run ``fn`` (a training entry point) with torch on at most 2 threads (the count its record names, on which its
    weights' last bits depend) and give the caller its own thread count back afterwards."""
    import functools

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        with torch_threads(max(1, min(2, torch.get_num_threads()))):
            return fn(*args, **kwargs)

    return wrapped


def lr_factor(schedule: str, fraction: float) -> float:
    """Learning-rate multiplier after ``fraction`` of the run (its steps, or its wall-time budget): 1 throughout
    for ``"constant"``; for ``"cosine"`` from 1 down to ``LR_FLOOR`` along half a cosine, and ``LR_FLOOR`` past the
    budget."""
    if schedule == "constant":
        return 1.0
    if schedule != "cosine":
        raise DoefabError(f"unknown learning-rate schedule {schedule!r}: use one of {', '.join(SCHEDULES)}")
    f = min(max(float(fraction), 0.0), 1.0)
    # a Python float, not numpy's: the optimiser state goes into checkpoints loaded with weights_only=True
    return float(LR_FLOOR + (1.0 - LR_FLOOR) * 0.5 * (1.0 + np.cos(np.pi * f)))


def run_loop(out: Path, config: dict, minutes: float, step_fn: Callable[[int], float], validate: Callable[[], float],
             states: dict, optimizers: list, schedule: str = "cosine", metric: str = "metric", val_every: int = 50,
             resume: bool = False, progress: bool = True, desc: str = "train", max_steps: int | None = None,
             tensors: dict | None = None, validate_first: bool = False) -> tuple[int, list, float]:
    """Train until ``minutes`` of wall time (or ``max_steps``) pass; returns (steps, history, seconds). The learning
    rate's ``schedule`` runs over ``max_steps`` where given (a run, and a resumed one, then repeat bit for bit at a
    fixed thread count), else over the time budget.

    ``step_fn(step) → loss`` takes one step (its optimisers' rates are already set); ``validate() → metric``;
    ``states``: {name: object with state_dict/load_state_dict} (modules and optimisers) to checkpoint;
    ``optimizers``: [(optimizer, base learning rate)] the schedule drives; ``tensors``: {name: tensor} also
    checkpointed and restored in place; ``validate_first``: a fresh run's history opens with the metric before
    any step (step 0).
    """
    from doefab.design.checkpoint import clear_checkpoint, save_checkpoint

    lr_factor(schedule, 0.0)  # an unknown schedule fails before any work
    out.mkdir(parents=True, exist_ok=True)
    ckpt = out / "checkpoint.pt"
    clear_checkpoint(out, keep=resume)  # a fresh run: an earlier run's checkpoint there must not be resumed later
    tensors = tensors or {}
    step, elapsed, history, finished = _resumed(ckpt, config, states, tensors) if resume else (0, 0.0, [], False)
    budget, start = minutes * 60.0, step
    t0 = time.perf_counter() - elapsed

    def save(step_now: int, done: bool = False) -> None:
        save_checkpoint(ckpt, {"config": json.dumps({"config": config}, sort_keys=True), "step": step_now,
                               "finished": done,
                               "elapsed": float(time.perf_counter() - t0), "history": history,
                               "generator": torch.get_rng_state(),
                               **{k: v.state_dict() for k, v in states.items()},
                               **{k: v.detach().clone() for k, v in tensors.items()}})
        lines = [f"step,wall_time_s,loss,val_{metric}"] + [",".join(f"{v:.6g}" for v in r) for r in history]
        atomic_write_text(out / "history.csv", "\n".join(lines) + "\n")

    if validate_first and not history:
        history.append([0, 0.0, float("nan"), validate()])
    bar = _bar(progress, budget, elapsed, desc, max_steps, step)
    last = history[-1][3] if history else float("nan")
    validated = validate_first or step >= val_every  # the bar shows a dash until the metric exists
    try:
        while time.perf_counter() - t0 < budget and (max_steps is None or step < max_steps):
            # the schedule follows the steps when they are counted (the same rates, so the same weights, every run
            # and on resume; the clock then only stops a run early), else the time budget
            f = lr_factor(schedule, step / max_steps if max_steps else (time.perf_counter() - t0) / budget)
            for opt, base in optimizers:
                for group in opt.param_groups:
                    group["lr"] = base * f
            loss = step_fn(step)
            if not np.isfinite(loss):
                raise DoefabError(f"training loss became {loss} at step {step}; the last checkpoint is kept in "
                                  f"{ckpt} (lower the learning rate)")
            step += 1
            if step % val_every == 0:
                last, validated = validate(), True
            history.append([step, round(time.perf_counter() - t0, 2), float(loss), last])
            if step % val_every == 0:
                save(step)
            if bar is not None:
                bar.n = step if max_steps else int(min(time.perf_counter() - t0, budget))
                bar.set_postfix(step=step, loss=f"{loss:.4f}", **{metric: f"{last:.4g}" if validated else "–"})
                bar.refresh()
    finally:
        if bar is not None:
            bar.close()
    if finished and step == start:
        return step, history, elapsed  # a finished run resumed: its last row is this state's validation already
    final = validate()
    history.append([step, round(time.perf_counter() - t0, 2), history[-1][2] if history else float("nan"), final])
    save(step, done=True)
    return step, history, time.perf_counter() - t0


def _resumed(ckpt: Path, config: dict, states: dict, tensors: dict) -> tuple[int, float, list, bool]:
    """(step, elapsed seconds, history, finished) of a checkpoint made with the same ``config`` (else a clear
    refusal), its ``states`` and ``tensors`` restored in place; finished: saved at the end of its run, after the
    last validation."""
    from doefab.design.checkpoint import load_checkpoint

    state = load_checkpoint(ckpt, {"config": config}, ignore=())
    for name, obj in states.items():
        obj.load_state_dict(state[name])
    with torch.no_grad():
        for name, t in tensors.items():
            t.copy_(state[name])
    return (int(state["step"]), float(state["elapsed"]), [list(r) for r in state["history"]],
            bool(state.get("finished", False)))


def _bar(progress: bool, budget: float, elapsed: float, desc: str, max_steps: int | None = None, step: int = 0):
    """The run's progress bar: its steps when they are counted, else the time budget's seconds."""
    if not progress:
        return None
    from tqdm import tqdm

    if max_steps:
        return tqdm(total=max_steps, initial=min(step, max_steps), desc=desc, unit="step")

    # the bar counts the time budget's seconds: no rate ("s/s"), the steps and metrics as its postfix
    return tqdm(total=int(budget), initial=int(min(elapsed, budget)), desc=desc, unit="s",
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} s [{elapsed}<{remaining}{postfix}]")
