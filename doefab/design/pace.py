"""How long a design run takes on this machine: a few of its own steps timed and scaled to its iterations.

``design_time`` sets the run up exactly as ``optimize`` would (``optimize.prepare_run``: the same task, camera,
grid, batch and device), takes one step to fill the plan's caches, times ``steps`` more (their median: a stray slow
step does not scale to the whole run) and one evaluation of the full metric, and adds them up as the run spends
its time:

- the set-up and first step, beyond an ordinary step (the PSF plan, the start);
- ``iterations`` steps (Adam: one batch of (depth, wavelength) pairs and its gradient; nlopt: one evaluation over
  every pair and its gradient);
- the full metric every ``eval_every`` steps and at the last (``DesignRun.record``);
- the finish (``finish.finish_design``): two PSF sets over every pair on the camera's full grid, counted as two
  full metrics scaled by the grid's area (``sampling``², the coarsened grid's pixels to the full one's).

The estimate holds for the machine's load when it was measured (a busy machine runs slower) and counts Adam's
steps at the pace of the first ones (a quantization-aware step costs the same PSFs). Nothing is written; the steps
taken are thrown away.
"""

from __future__ import annotations

import time

__all__ = ["design_time"]


def design_time(task="streak", iterations: int | None = None, optimizer: str = "adam", seed: int = 0,
                camera=None, device=None, steps: int = 3, **settings) -> dict:
    """The wall time of ``optimize(task, iterations, optimizer, seed, camera, device=device, **settings)`` on this
    machine, from ``steps`` of its own steps (module docstring).

    Returns:
        {"seconds": the whole run (s), "step_s": one step, the median of those timed (s), "metric_s": one full
        metric evaluation (s), "setup_s": set-up and first step beyond a step (s), "iterations": the run's steps,
        "evaluations": its full metric evaluations, "grid_px": the side of the grid it optimises on, "device"}.

    Example:
        The streak on a coarse 256-pixel grid, 100 Adam steps:

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
        >>> t = doefab.design_time("streak", iterations=100, camera=cam)
        >>> t["iterations"], t["evaluations"], t["seconds"] > 100 * t["step_s"] > 0
        (100, 6, True)
    """
    from doefab.design.optimize import prepare_run
    from doefab.validate import number_in

    number_in("steps", steps, 1, 1000, True)
    t0 = time.perf_counter()
    run = prepare_run(task, iterations, optimizer, seed, camera, None, device, **settings)
    run.one_step(0)
    _sync(run.dev)
    setup = time.perf_counter() - t0
    times = []
    for i in range(1, steps + 1):
        t = time.perf_counter()
        run.one_step(i)
        _sync(run.dev)
        times.append(time.perf_counter() - t)
    t = time.perf_counter()
    run.full_metric(False)
    _sync(run.dev)
    metric = time.perf_counter() - t
    step = sorted(times)[(len(times) - 1) // 2]  # the median (of an even count, the lower middle one)
    cfg = run.cfg
    evals = len(range(0, cfg.iterations, cfg.eval_every)) + int((cfg.iterations - 1) % cfg.eval_every != 0)
    finish = 2 * cfg.sampling ** 2 * metric
    return {"seconds": max(setup - step, 0.0) + cfg.iterations * step + evals * metric + finish, "step_s": step,
            "metric_s": metric, "setup_s": max(setup - step, 0.0), "iterations": cfg.iterations,
            "evaluations": evals, "grid_px": run.dcam.doe_pixels, "device": str(run.dev)}


def _sync(device) -> None:
    """Wait for the device's queued work (CUDA runs asynchronously), so that a clock reads its time."""
    import torch

    if torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)
