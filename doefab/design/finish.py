"""The finished design: the optimised heights upsampled to the camera's DOE grid, quantized to the fab's levels
(the plain half and the area outside the clear aperture at the top level) and evaluated at full resolution.

Example: ``finalize_levels(height, camera, 16)`` → the (N, N) level map a mask set is written from.
"""

from __future__ import annotations

import numpy as np
import torch

from doefab.design.design import Design
from doefab.design.parameterization import make_parameterization, theta_to_height
from doefab.fabrication.levels import level_step, quantize_levels
from doefab.fabrication.process import DEFAULT_LEVELS
from doefab.optics.camera import Camera
from doefab.optics.psf import PSFPlan
from doefab.optics.pupil import pupil_half

__all__ = ["coded_mask", "plain_level", "finalize_levels", "finish_design"]


def coded_mask(camera: Camera) -> torch.Tensor:
    """(N, N) float mask of DOE pixels that carry coded light (inside the aperture, x < 0)."""
    geo = pupil_half(camera, "coded")
    m = np.zeros((camera.doe_pixels,) * 2)
    m[geo.rows, geo.cols] = geo.coverage > 0
    return torch.from_numpy(m).float()


def plain_level(n_levels: int) -> int:
    """The level of the plain half and of the area outside the clear aperture: the top one (left unetched)."""
    return n_levels - 1


def finalize_levels(height: np.ndarray, camera: Camera, n_levels: int = DEFAULT_LEVELS) -> np.ndarray:
    """Levels of a design: nearest of ``n_levels`` levels in the coded aperture, the plain level elsewhere."""
    lv = quantize_levels(height, camera, n_levels)
    mask = coded_mask(camera).numpy() > 0
    lv[~mask] = plain_level(n_levels)
    return lv


def finish_design(task_obj, cfg, cam, dcam, theta, param, history, lams, depths, device=None) -> Design:
    """Upsample to the preset grid, quantize, and evaluate continuous and quantized metrics at full resolution
    (the PSFs on ``device``).

    A radial profile is evaluated on the full grid (its knots sit at fixed radii), not repeated per coarse pixel."""
    radial = cfg.parameterization == "radial"
    theta, param = theta.cpu(), param.to("cpu")
    with torch.no_grad():
        if radial:
            h_design = theta_to_height(make_parameterization("radial", cam, param.knots).waves(theta), cam)
        else:
            h_design = theta_to_height(param.waves(theta), dcam)
    h_design = h_design.double().numpy()
    if cfg.sampling > 1 and not radial:
        h_design = np.kron(h_design, np.ones((cfg.sampling, cfg.sampling)))
    n_levels = cfg.n_levels
    levels = finalize_levels(h_design, cam, n_levels)
    mask = coded_mask(cam).numpy() > 0
    step = level_step(cam, n_levels)
    height = np.where(mask, h_design, plain_level(n_levels) * step)
    plan = PSFPlan(cam, lams, depths, task_obj.kernel_size, halves=("coded",), device=device)
    with torch.no_grad():
        psf_c = plan(height).coded
        psf_q = plan(levels.astype(np.float64) * step).coded
    mc, mq = task_obj.metric(psf_c, cam), task_obj.metric(psf_q, cam)
    metrics = {"name": task_obj.metric_name, "continuous": mc["value"], "quantized": mq["value"],
               "continuous_worst": mc["worst"], "quantized_worst": mq["worst"],
               "per_entry_axes": ["depth", "wavelength"],
               "per_entry": {"continuous": mc["per_entry"], "quantized": mq["per_entry"]},
               "loss_kind": task_obj.loss_kind}
    return Design(task=task_obj.name, task_params=task_obj.params(), camera=cam, wavelengths=tuple(lams),
                  depths=tuple(depths), height=height, levels=levels, metrics=metrics, seed=cfg.seed,
                  optimizer=cfg.optimizer, iterations=cfg.iterations, history=history,
                  psf_quantized=psf_q.numpy(), targets=task_obj.targets(cam).numpy(), n_levels=n_levels,
                  extra={"config": cfg.key(), **({"radial_knots_waves": [round(float(v), 6) for v in theta]}
                                                 if radial else {})})
