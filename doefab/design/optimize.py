"""Design optimisation: any task, Adam (torch) or nlopt (L-BFGS / MMA) behind one interface.

The loop sees only the task interface (wavelengths, depths, kernel, loss, metric, init), so a new task
needs no change here. Heights are parameterised in waves and wrapped (``parameterization``); a final
quantization-aware stage uses a straight-through estimator around the mask export's rounding. Runs
checkpoint every N steps and resume exactly (Adam; nlopt resumes from the last checkpointed point); a
non-finite loss stops the run with an error and keeps the last good checkpoint.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from doefab._devices import resolve_device
from doefab.design.checkpoint import clear_checkpoint, load_checkpoint, save_checkpoint
from doefab.design.design import Design
from doefab.design.finish import coded_mask, finalize_levels, finish_design, plain_level
from doefab.design.nloptrun import check_nlopt_size, run_nlopt
from doefab.design.parameterization import (STARTS, isolated_pixel_penalty, make_parameterization, quantize_ste,
                                            theta_to_height)
from doefab.errors import DoefabError
from doefab.fabrication.process import DEFAULT_LEVELS, check_levels
from doefab.optics.camera import Camera, require_camera
from doefab.optics.psf import PSFPlan
from doefab.tasks import get_task

__all__ = ["DesignConfig", "optimize", "prepare_run", "DesignRun", "design_from_theta", "plain_level", "OPTIMIZERS",
           "coded_mask", "finalize_levels", "sampling_problem", "design_camera"]

OPTIMIZERS = ("adam", "lbfgs", "mma")


@dataclass
class DesignConfig:
    """Settings of one design run (all JSON-serialisable; a checkpoint must match them to resume).

    Attributes:
        task: task name.  task_params: task parameters (JSON).  iterations: optimiser steps.
        optimizer: adam, lbfgs or mma.  lr: Adam step in waves.  seed: RNG seed.
        sampling: DOE grid coarsening factor during the design (1 = the preset's grid, 2 = half).
        qat_fraction: last fraction of the steps run quantization-aware (0 = off).
        batch: number of (depth, wavelength) pairs per Adam step (0 = all; a random subset otherwise;
            -1 = every depth with one random wavelength each, so the worst depth is always seen).
        fab_weight: weight of the isolated-pixel regulariser (0 = off).
        checkpoint_every: steps between checkpoints.  eval_every: steps between full metric evaluations.
        parameterization: ``"pixel"`` (one phase per DOE pixel) or ``"radial"`` (a rotationally symmetric
            profile, ``doefab.design.parameterization.RadialParam``).  knots: radial knot count (0 = N/2).
        start: ``"task"`` (the task's own starting map) or ``"lens"`` (the thin lens that refocuses the coded
            half to the task's farthest depth); ``None`` = task for pixel, lens for radial.
        n_levels: the levels the fab makes (2, 4, 8, 16 or 32; log2 L masks): the quantization-aware stage and
            the finished design round to them.
    """

    task: str = "streak"
    task_params: dict | None = None
    iterations: int = 200
    optimizer: str = "adam"
    lr: float = 0.02
    seed: int = 0
    sampling: int = 1
    qat_fraction: float = 0.2
    batch: int = 0
    fab_weight: float = 0.0
    checkpoint_every: int = 20
    eval_every: int = 20
    parameterization: str = "pixel"
    knots: int = 0
    start: str | None = None
    n_levels: int = DEFAULT_LEVELS

    def check(self) -> None:
        """Every numeric setting within its range (one error naming it), before any work."""
        from doefab.validate import number_in

        for name, lo, hi, integer in (("iterations", 1, 1_000_000, True), ("lr", 0, 10, False),
                                      ("seed", 0, 2**32 - 1, True), ("sampling", 1, 16, True),
                                      ("qat_fraction", 0, 1, False), ("batch", -1, 100_000, True),
                                      ("fab_weight", 0, 1000, False), ("checkpoint_every", 1, 10**9, True),
                                      ("eval_every", 1, 10**9, True), ("knots", 0, 100_000, True)):
            number_in(name, getattr(self, name), lo, hi, integer, lo_open=name == "lr")
        if self.knots == 1:
            raise DoefabError("knots must be 0 (one per design-grid pixel along the radius) or at least 2")
        check_levels(self.n_levels, "n_levels")

    def key(self) -> dict:
        """The settings a checkpoint must match (all but how often it is written and the metric evaluated)."""
        return {k: v for k, v in asdict(self).items() if k not in ("eval_every", "checkpoint_every")}


def sampling_problem(doe_pixels: int, sampling: int, key: str = "sampling") -> str | None:
    """Why ``sampling`` cannot coarsen a ``doe_pixels``-wide DOE grid (None: it can), with the factors that can.

    Example: ``sampling_problem(2234, 4)`` names 1 and 2, the factors up to 16 that divide 2234.
    """
    if doe_pixels % sampling == 0:
        return None
    fits = [d for d in range(1, 17) if doe_pixels % d == 0]
    return (f"{key} {sampling} must divide the DOE grid ({doe_pixels} px): use "
            f"{' or '.join(map(str, fits))}, or a DOE pitch or aperture whose grid it divides")


def design_camera(camera: Camera, sampling: int) -> Camera:
    """The camera a design is optimised on: the DOE grid coarsened by ``sampling`` (pixels / s, pitch × s); one
    error when ``sampling`` does not divide the grid. Example: ``design_camera(cam, 2).doe_pitch == 2 * cam.doe_pitch``.
    """
    if sampling == 1:
        return camera
    problem = sampling_problem(camera.doe_pixels, sampling)
    if problem:
        raise DoefabError(problem)
    return camera.replace(doe_pixels=camera.doe_pixels // sampling, doe_pitch=camera.doe_pitch * sampling)


def optimize(task="streak", iterations: int | None = None, optimizer: str = "adam", seed: int = 0,
             camera: Camera | None = None, out_dir: str | Path | None = None, resume: bool = False,
             progress: bool = True, device=None, replace: tuple = (), **settings) -> Design:
    """Optimise a task's coded height map and return the quantized design.

    Args:
        task: ``"streak"``, ``"grating"``, ``"half-ring"`` or a Task object.
        iterations: optimiser steps (function evaluations for nlopt); default: the task's.
        optimizer: ``"adam"`` (default), ``"lbfgs"`` or ``"mma"`` (nlopt, driven by torch gradients).
        seed: RNG seed; the same seed and settings give the same design.
        camera: defaults to the task's preset camera.
        out_dir: folder for ``checkpoint.pt`` and ``history.csv`` while running (None: no checkpoints).
        resume: continue from ``out_dir/checkpoint.pt``.
        replace: names of an earlier run's files in ``out_dir`` (a finished design's, ``design.DESIGN_FILES``)
            removed as a fresh run starts there, after every check (``doefab design --force``).
        device: where the PSFs and gradients are computed ("auto", "cpu", "cuda", "cuda:N"; None: the current
            default, ``doefab._devices.default_device``). The random batches are drawn on the CPU, so a seed gives
            the same steps on every device (the numbers agree to float32 rounding).
        **settings: other :class:`DesignConfig` fields (lr, sampling, qat_fraction, batch, fab_weight, …).

    Example:
        Two Adam steps of the streak on a coarse 256-pixel grid (a real design takes the task's default steps on
        the preset's grid), quantized to the default 16 levels:

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
        >>> design = doefab.optimize("streak", iterations=2, camera=cam, progress=False)
        >>> design.levels.shape, design.n_levels
        ((256, 256), 16)
    """
    run = prepare_run(task, iterations, optimizer, seed, camera, out_dir, device, **settings)
    if resume:
        run.resume()
    elif out_dir is not None:
        clear_checkpoint(out_dir)  # a fresh run: an earlier run's checkpoint there must not be resumed later
        for name in replace:  # and its results, so an interrupt leaves nothing complete-looking of that run
            (Path(out_dir) / name).unlink(missing_ok=True)
    return run.run(progress)


def prepare_run(task="streak", iterations: int | None = None, optimizer: str = "adam", seed: int = 0,
                camera: Camera | None = None, out_dir: str | Path | None = None, device=None,
                **settings) -> DesignRun:
    """The ``DesignRun`` that ``optimize`` runs with these arguments (the same defaults and checks), set up and
    not yet run: ``.run()`` optimises, ``.one_step(i)`` takes step ``i`` alone (``design.pace`` times it)."""
    task_obj = get_task(task, **(settings.pop("task_params", None) or {}))
    iterations = task_obj.default_iterations if iterations is None else iterations
    settings.setdefault("lr", task_obj.default_lr)
    settings.setdefault("batch", task_obj.default_batch if optimizer == "adam" else 0)
    if optimizer not in OPTIMIZERS:
        raise DoefabError(f"unknown optimizer {optimizer!r}: choose one of {OPTIMIZERS}")
    unknown = set(settings) - set(DesignConfig.__dataclass_fields__)
    if unknown:
        raise DoefabError(f"unknown design settings {sorted(unknown)}")
    cfg = DesignConfig(task=task_obj.name, task_params=task_obj.params(), iterations=iterations, optimizer=optimizer,
                       seed=seed, **settings)
    cfg.check()
    dev = resolve_device(device)
    cam = Camera.preset(task_obj.preset) if camera is None else require_camera(camera)
    task_obj.bind(cam)
    if problem := task_obj.window_problem(cam):  # the targets and metric would be cut at the window's edge
        raise DoefabError(problem)
    cfg.task_params = task_obj.params()
    if cfg.start is None:
        cfg.start = "lens" if cfg.parameterization == "radial" else "task"
    if cfg.start not in STARTS:
        raise DoefabError(f"unknown start {cfg.start!r}: choose one of {STARTS}")
    run = DesignRun(task_obj, cfg, cam, out_dir, dev)
    if cfg.optimizer != "adam":  # refused before any step (and before design_time times one)
        check_nlopt_size(cfg.optimizer, run.param.variable_mask(run.mask))
    return run


class DesignRun:
    """One design optimisation: set up from a checked ``DesignConfig`` (the start drawn with its seed), optionally
    resumed from ``out_dir/checkpoint.pt``, then ``run``: the optimiser's steps (Adam here, nlopt through
    ``nloptrun.run_nlopt``), each recorded and checkpointed, and the quantized design."""

    def __init__(self, task_obj, cfg: DesignConfig, cam: Camera, out_dir, dev):
        self.task, self.cfg, self.cam, self.dev = task_obj, cfg, cam, dev
        self.dcam = dcam = design_camera(cam, cfg.sampling)
        self.param = make_parameterization(cfg.parameterization, dcam, cfg.knots).to(dev)
        torch.manual_seed(cfg.seed)
        rng = np.random.default_rng(cfg.seed)
        self.lams, self.depths = task_obj.wavelengths(dcam), task_obj.depths(dcam)
        self.plan = PSFPlan(dcam, self.lams, self.depths, task_obj.kernel_size, halves=("coded",), device=dev)
        self.mask = coded_mask(dcam).to(dev)
        self.theta = self.param.start(task_obj, rng, cfg.start).to(dev).requires_grad_(True)
        self.pairs = [(d, w) for d in range(len(self.depths)) for w in range(len(self.lams))]
        self.gen = torch.Generator().manual_seed(cfg.seed)
        self.history: list = []
        self.step0, self.elapsed0 = 0, 0.0
        self.ckpt = Path(out_dir) / "checkpoint.pt" if out_dir is not None else None
        self.config_json = json.dumps(cfg.key(), sort_keys=True)
        self.adam = torch.optim.Adam([self.theta], lr=cfg.lr) if cfg.optimizer == "adam" else None
        self.qat_start = (int(round(cfg.iterations * (1 - cfg.qat_fraction))) if cfg.qat_fraction > 0
                          else cfg.iterations)
        self.bar, self.t_start, self.last_metric = None, 0.0, float("nan")

    def resume(self) -> None:
        """θ, the optimiser's state, the batches' generator and the history from ``checkpoint.pt``."""
        ckpt, cfg, theta = self.ckpt, self.cfg, self.theta
        if ckpt is None:
            raise DoefabError("resume needs out_dir (where checkpoint.pt lives)")
        state = load_checkpoint(ckpt, json.loads(self.config_json), ignore=("iterations",))
        if tuple(state["theta"].shape) != tuple(theta.shape):
            raise DoefabError(f"checkpoint {ckpt} holds a {tuple(state['theta'].shape)} design, this run a "
                              f"{tuple(theta.shape)} one: start a new --out folder")
        before = json.loads(state["config"]).get("iterations")
        if isinstance(before, int) and cfg.iterations < before:  # its quantization-aware steps would not all run
            raise DoefabError(f"checkpoint {ckpt} is of a run of {before} iterations: a resume may raise "
                              f"--iterations, not lower it (to {cfg.iterations}); start afresh for a shorter run")
        with torch.no_grad():
            theta.copy_(state["theta"])
        if self.adam is not None and "adam" in state:
            self.adam.load_state_dict(state["adam"])
        self.gen.set_state(state["generator"])
        self.step0, self.elapsed0 = int(state["step"]), float(state["elapsed"])
        self.history = [list(r) for r in state["history"]]

    def objective(self, step: int, batch_pairs=None):
        """The task's loss at ``step`` (quantization-aware from ``qat_start``) over ``batch_pairs`` (None: all)."""
        task_obj, dcam, plan, cfg = self.task, self.dcam, self.plan, self.cfg
        h = theta_to_height(self.param.waves(self.theta), dcam)
        if step >= self.qat_start:
            h = quantize_ste(h, dcam, cfg.n_levels)
        if batch_pairs is None:
            psf = plan.half_psf("coded", h)
            loss = task_obj.loss(psf, dcam)
        elif task_obj.loss_kind in ("band", "window"):
            # one loss over the whole batch, so the window loss's soft minimum compares its entries
            frac = torch.cat([task_obj.fractions(plan.half_psf("coded", h, depth_indices=[d], wavelength_indices=[w]),
                                                 dcam, [d], [w]).flatten() for d, w in batch_pairs])
            loss = task_obj.loss_from_fractions(frac)
        else:
            loss = 0.0
            for d, w in batch_pairs:
                psf = plan.half_psf("coded", h, depth_indices=[d], wavelength_indices=[w])
                loss = loss + task_obj.loss(psf, dcam, [d], [w]) / len(batch_pairs)
        if cfg.fab_weight > 0:
            loss = loss + cfg.fab_weight * isolated_pixel_penalty(self.param.waves(self.theta), self.mask)
        return loss

    def full_metric(self, quantized: bool) -> dict:
        with torch.no_grad():
            h = theta_to_height(self.param.waves(self.theta), self.dcam)
            if quantized:
                h = quantize_ste(h, self.dcam, self.cfg.n_levels)
            return self.task.metric(self.plan.half_psf("coded", h), self.dcam)

    def checkpoint(self, step: int, elapsed: float) -> None:
        if self.ckpt is None:
            return
        state = {"config": self.config_json, "theta": self.theta.detach().cpu().clone(), "step": step,
                 "elapsed": elapsed, "generator": self.gen.get_state(), "history": self.history}
        if self.adam is not None:
            state["adam"] = self.adam.state_dict()
        save_checkpoint(self.ckpt, state)

    def record(self, step: int, loss_value: float) -> None:
        """One evaluation into the history (the full metric every ``eval_every``), the bar and the checkpoint."""
        cfg, ckpt = self.cfg, self.ckpt
        if not math.isfinite(loss_value):
            raise DoefabError(f"the loss became {loss_value} at step {step}: stopping; the last good checkpoint "
                              f"is kept{'' if ckpt is None else ' in ' + str(ckpt)} (lower the learning rate)")
        if step % cfg.eval_every == 0 or step == cfg.iterations - 1:
            self.last_metric = self.full_metric(step >= self.qat_start)["value"]
        self.history.append([step, round(time.perf_counter() - self.t_start, 3), loss_value, self.last_metric])
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(loss=f"{loss_value:.4f}", metric=f"{self.last_metric:.4f}")
        if (step + 1) % cfg.checkpoint_every == 0:
            self.checkpoint(step + 1, time.perf_counter() - self.t_start)

    def next_batch(self):
        """The (depth, wavelength) pairs of the next Adam step, drawn with the run's generator (None: all)."""
        cfg, gen, pairs = self.cfg, self.gen, self.pairs
        if cfg.batch < 0:  # stratified: every depth, one random wavelength each
            wl = torch.randint(len(self.lams), (len(self.depths),), generator=gen).tolist()
            return [(d, wl[d]) for d in range(len(self.depths))]
        if 0 < cfg.batch < len(pairs):
            idx = torch.randperm(len(pairs), generator=gen)[:cfg.batch].tolist()
            return [pairs[i] for i in sorted(idx)]
        return None

    def one_step(self, step: int) -> torch.Tensor:
        """Step ``step`` of the optimiser without recording it: Adam's on its next batch, else (nlopt) one
        evaluation of the objective over every pair and its gradient. Returns the loss."""
        if self.adam is None:
            self.theta.grad = None
            loss = self.objective(step)
            loss.backward()
            return loss.detach()
        self.adam.zero_grad()
        loss = self.objective(step, self.next_batch())
        if not torch.isfinite(loss):
            self.record(step, float(loss.detach()))
        loss.backward()
        self.adam.step()
        return loss.detach()

    def _adam_steps(self) -> None:
        for step in range(self.step0, self.cfg.iterations):
            self.record(step, float(self.one_step(step)))

    def run(self, progress: bool = True) -> Design:
        """The optimiser's steps from ``step0``, then the quantized design (``finish.finish_design``) with its run
        times."""
        cfg = self.cfg
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=cfg.iterations, initial=self.step0, desc=f"design {self.task.name} "
                            f"({cfg.optimizer})", unit="step")
        self.t_start = time.perf_counter() - self.elapsed0
        self.last_metric = self.history[-1][3] if self.history else float("nan")
        stop_reason = None
        try:
            if cfg.optimizer == "adam":
                self._adam_steps()
            else:
                stop_reason = run_nlopt(cfg.optimizer, self.theta, self.objective, self.record, self.step0,
                                        cfg.iterations, self.qat_start, self.param.variable_mask(self.mask))
        finally:
            if self.bar is not None:
                self.bar.close()
        self.checkpoint(cfg.iterations, time.perf_counter() - self.t_start)
        design = finish_design(self.task, cfg, self.cam, self.dcam, self.theta.detach(), self.param, self.history,
                               self.lams, self.depths, self.dev)
        design.extra["wall_time_s"] = round(time.perf_counter() - self.t_start, 1)
        design.extra["optimizer_time_s"] = self.history[-1][1] if self.history else 0.0
        design.extra["evaluations"] = len(self.history)
        if stop_reason:
            design.extra["stop_reason"] = stop_reason
        return design


def design_from_theta(design: Design, theta: torch.Tensor, parameterization: str, sampling: int, history=(),
                      extra: dict | None = None, device=None) -> Design:
    """A finished design (full-grid heights, ``design``'s levels, full-grid metrics, the PSFs computed on ``device``)
    of ``design``'s task and camera from parameters θ found on its grid coarsened ``sampling`` times (e.g. by
    end-to-end fine-tuning)."""
    task_obj = get_task(design.task, **design.task_params)
    task_obj.bind(design.camera)
    radial = parameterization == "radial"
    cfg = DesignConfig(task=task_obj.name, task_params=task_obj.params(), iterations=max(len(history), 1),
                       seed=design.seed, sampling=sampling, parameterization=parameterization,
                       knots=int(theta.numel()) if radial else 0, start="task", n_levels=design.n_levels)
    dcam = design_camera(design.camera, sampling)
    param = make_parameterization(parameterization, dcam, cfg.knots)
    out = finish_design(task_obj, cfg, design.camera, dcam, theta, param, list(history), design.wavelengths,
                        design.depths, device)
    out.extra.update(extra or {})
    return out
