"""End-to-end fine-tuning of a depth DOE together with its depth network (as the paper's authors do in their
release): the loss is the network's depth error, and its gradient flows through the captures and the PSFs into
the DOE's phase.

Starting point: a task-loss design (its radial knots when it is a radial design, else its L-level map as pixel
phases) and, optionally, a network already trained for it. Each step renders a batch of layered depth scenes
with the current coded PSF (occlusion-aware layer compositing, ``doefab.imaging.captures.render_layers``, which
is differentiable), adds sensor noise as a Gaussian with the Poisson–Gaussian variance (the reparameterised
form, so gradients pass), and trains the network on L1 + gradient depth loss (the paper's Eq. 28). Every
``doe_every``-th step the PSF is recomputed *with* gradients and the DOE takes an Adam step too (quantization-
aware: straight-through rounding to the design's L levels, as the masks make them); the other steps reuse the
last PSF, since one PSF with gradients costs as much as many network steps on this CPU. The PSFs are computed on
the design grid coarsened ``sampling`` times (as the design stage does); the finished DOE is re-evaluated on the
full grid.
Checkpoints every ``val_every`` steps; ``resume`` continues exactly. ``device`` says where the PSFs, the rendering
and the network run; the scenes and the noise are drawn on the CPU (seeded), so a run takes the same steps on every
device.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from doefab.applications import design_is
from doefab.errors import DoefabError
from doefab.reconstruction.loop import training_threads

__all__ = ["finetune_end_to_end", "render_depth_batch"]


def render_depth_batch(indices, split: str, size: int, psf_coded: torch.Tensor, psf_uncoded: torch.Tensor,
                       depths, margin: int, noise_seed: int, full_well: float | None = None,
                       read_noise: float | None = None):
    """(coded, uncoded, depth) for depth scenes ``indices`` of ``split``, differentiable in ``psf_coded``, on
    ``psf_coded``'s device; ``full_well``, ``read_noise``: electrons (default: the default sensor's)."""
    from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E
    from doefab.imaging.captures import plane_masks, render_layers
    from doefab.reconstruction.data import depth_sample, sample_rng

    full_well = DEFAULT_FULL_WELL_E if full_well is None else full_well
    read_noise = DEFAULT_READ_NOISE_E if read_noise is None else read_noise
    big = size + 2 * margin
    dev = psf_coded.device
    gen = torch.Generator().manual_seed(int(noise_seed))
    out_c, out_u, out_d = [], [], []
    for i in indices:
        scene, depth = depth_sample(sample_rng(split, i), big, split)
        masks = plane_masks(torch.from_numpy(depth).to(dev), depths)
        s = torch.from_numpy(scene).to(dev)
        views = []
        for psf in (psf_coded, psf_uncoded):
            b = render_layers(s, psf.to(torch.float32), masks, depths)[:, margin:margin + size, margin:margin + size]
            sigma = torch.sqrt(b.clamp_min(0) / full_well + (read_noise / full_well) ** 2)
            views.append((b + sigma * torch.randn(b.shape, generator=gen).to(dev)).clamp(0, 1))
        out_c.append(views[0])
        out_u.append(views[1])
        out_d.append(torch.from_numpy(np.ascontiguousarray(depth[margin:margin + size, margin:margin + size])).to(dev))
    return torch.stack(out_c), torch.stack(out_u), torch.stack(out_d)


def _start_theta(design, param_name: str, dcam, sampling: int) -> tuple[torch.Tensor, object]:
    from doefab.design.parameterization import make_parameterization

    cfg = design.extra.get("config", {})
    if param_name == "radial":
        knots = design.extra.get("radial_knots_waves")
        if cfg.get("parameterization") != "radial" or not knots:
            raise DoefabError("radial end-to-end fine-tuning needs a radial design (its design.json holds "
                              "radial_knots_waves): design one with doefab design --parameterization radial")
        param = make_parameterization("radial", dcam, len(knots))
        return torch.tensor(knots, dtype=torch.float32), param
    param = make_parameterization("pixel", dcam)
    n = dcam.doe_pixels
    phase = np.exp(2j * np.pi * design.levels.astype(np.float64) / design.n_levels)  # level l: l/L of a wave
    phase = phase.reshape(n, sampling, n, sampling).mean(axis=(1, 3))
    return torch.from_numpy(np.angle(phase) / (2 * np.pi)).float(), param


@training_threads
def finetune_end_to_end(design_dir, out_dir, minutes: float = 20.0, weights_dir=None, doe_every: int = 4,
                        lr_doe: float = 0.01, lr_net: float = 2e-4, batch: int = 4, crop: int | None = None,
                        seed: int = 0,
                        val_images: int = 8, val_every: int = 20, sampling: int = 2, parameterization: str | None = None,
                        resume: bool = False, progress: bool = True, max_steps: int | None = None,
                        sensor=None, device=None) -> dict:
    """Fine-tune the DOE of ``design_dir`` and a depth network together for ``minutes`` of wall time.

    Writes ``out_dir/design/`` (the fine-tuned design, full-grid metrics), ``out_dir/weights/`` (the jointly trained
    network, loadable with ``load_reconstructor("depth", weights_dir=..., design=...)``), ``history.csv`` (step,
    wall time, loss, validation MAE in metres) and ``checkpoint.pt``. Returns a summary with the MAE gained per
    minute. ``crop``: the training crop side in pixels (default: the depth networks', ``TaskSpec.crop``).
    ``sensor``: the ``imaging.sensor.Sensor`` whose noise the captures carry (None: the default sensor's); a
    starting network trained for another sensor's noise is refused. ``device``: where the PSFs, the rendering and
    the network run ("auto", "cpu", "cuda", "cuda:N"; None: the current default, ``doefab._devices.default_device``).

    Example:

        >>> import inspect
        >>> from doefab import finetune_end_to_end
        >>> inspect.signature(finetune_end_to_end).parameters["minutes"].default  # wall time, minutes
        20.0
        >>> summary = finetune_end_to_end("masks/half-ring", "out/e2e", minutes=20)  # doctest: +SKIP
    """
    from doefab._devices import resolve_device
    from doefab.design.design import Design
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.loop import run_loop
    from doefab.reconstruction.specs import training_crop

    if not 0 < minutes <= 24 * 60:
        raise DoefabError(f"minutes must be in (0, 1440], got {minutes!r}")
    crop = training_crop("depth", crop)
    sensor = sensor or Sensor()
    dev = resolve_device(device)
    design = Design.load(design_dir)
    if not design_is(design.task, "depth"):
        raise DoefabError(f"end-to-end fine-tuning is for depth (half-ring) designs, got a {design.task} design")
    if design.camera.doe_pixels % sampling:
        raise DoefabError(f"sampling {sampling} must divide the DOE grid ({design.camera.doe_pixels} px)")
    pname = parameterization or ("radial" if design.extra.get("config", {}).get("parameterization") == "radial"
                                 else "pixel")
    run = _JointRun(design, design_dir, pname, sampling, weights_dir, sensor, seed, lr_doe, lr_net, dev)
    config = {"design": str(Path(design_dir).resolve()), "parameterization": pname, "sampling": sampling,
              "doe_every": doe_every, "lr_doe": lr_doe, "lr_net": lr_net, "batch": batch, "crop": crop, "seed": seed,
              "weights_dir": None if weights_dir is None else str(weights_dir), "val_images": val_images}
    config.update(sensor.entry(False))  # none for the default noise: old runs resume
    out = Path(out_dir)
    steps, history, wall = run_loop(
        out, config, minutes, lambda step: run.step(step, doe_every, batch, crop),
        lambda: run.validate(val_images, crop), {"model": run.net, "optimizer": run.opt_net,
                                                 "optimizer_doe": run.opt_doe},
        [(run.opt_net, lr_net), (run.opt_doe, lr_doe)], "constant", "mae_m", val_every, resume, progress,
        "end-to-end depth", max_steps, tensors={"theta": run.theta}, validate_first=True)
    start_mae, final = history[0][3], history[-1][3]
    new = run.write(out, config, {"from_design": config["design"], "minutes": minutes, "steps": steps,
                                  "doe_steps": math.ceil(steps / doe_every), "start_network": run.start_from}, wall)
    return {"steps": steps, "wall_time_s": round(wall, 1), "val_mae_start_m": start_mae, "val_mae_end_m": final,
            "mae_gain_per_minute_m": (start_mae - final) / (wall / 60.0), "design": str(out / "design"),
            "metric": new.metrics}


class _JointRun:
    """The DOE's parameters, the depth network, their optimisers and the PSFs of one end-to-end run: its
    validation, its training step and its outputs."""

    def __init__(self, design, design_dir, pname: str, sampling: int, weights_dir, sensor, seed: int,
                 lr_doe: float, lr_net: float, device):
        from doefab.optics.psf import PSFPlan
        from doefab.reconstruction.specs import crop_margin, psf_pair

        self.design, self.pname, self.sampling, self.seed, self.device = design, pname, sampling, seed, device
        self.noise = {"full_well": sensor.full_well_e, "read_noise": sensor.read_noise_e}
        self.sensor = sensor
        self.dcam = design.camera.replace(doe_pixels=design.camera.doe_pixels // sampling,
                                          doe_pitch=design.camera.doe_pitch * sampling)
        theta, param = _start_theta(design, pname, self.dcam, sampling)
        self.theta, self.param = theta.to(device).requires_grad_(True), param.to(device)
        nominal, _ = psf_pair("depth", design_dir)
        self.psf_u = nominal.uncoded.to(device, torch.float32)
        self.plan = PSFPlan(self.dcam, design.wavelengths, design.depths, nominal.coded.shape[-1], halves=("coded",),
                            device=device)
        self.margin = crop_margin("depth", nominal)
        torch.manual_seed(seed)
        self.net, self.arch, self.start_from = _start_network(design, design_dir, weights_dir, sensor)
        self.net.to(device)
        self.opt_net = torch.optim.Adam(self.net.parameters(), lr=lr_net)
        self.opt_doe = torch.optim.Adam([self.theta], lr=lr_doe)
        self.current = {}

    def coded_psf(self, grad: bool) -> torch.Tensor:
        from doefab.design.parameterization import quantize_ste, theta_to_height

        with torch.set_grad_enabled(grad):
            h = quantize_ste(theta_to_height(self.param.waves(self.theta), self.dcam), self.dcam,
                             self.design.n_levels)
            return self.plan.half_psf("coded", h)

    def validate(self, images: int, crop: int) -> float:
        psf_c = self.coded_psf(False)
        self.current["psf"] = psf_c
        c, u, d = render_depth_batch(range(images), "val", crop, psf_c, self.psf_u, self.design.depths, self.margin,
                                     noise_seed=self.seed + 1, **self.noise)
        self.net.eval()
        with torch.no_grad():
            mae = float((self.net(c, u, torch.stack([psf_c.float(), self.psf_u])) - d).abs().mean())
        self.net.train()
        return mae

    def step(self, step: int, doe_every: int, batch: int, crop: int) -> float:
        from doefab.reconstruction.models import loss_fn

        joint = step % doe_every == 0
        if joint:
            psf_c = self.coded_psf(True)
        else:
            if "psf" not in self.current:
                self.current["psf"] = self.coded_psf(False)
            psf_c = self.current["psf"]
        c, u, d = render_depth_batch(range(step * batch, (step + 1) * batch), "train", crop, psf_c, self.psf_u,
                                     self.design.depths, self.margin, noise_seed=self.seed * 1_000_003 + step,
                                     **self.noise)
        self.opt_net.zero_grad()
        self.opt_doe.zero_grad()
        # the cost volume sees the coded PSF too (differentiable in it on joint steps)
        loss = loss_fn("depth", self.net(c, u, torch.stack([psf_c.float(), self.psf_u])), d)
        if torch.isfinite(loss):
            loss.backward()
            self.opt_net.step()
            if joint:
                self.opt_doe.step()
                self.current["psf"] = self.coded_psf(False)
        return float(loss.detach())

    def write(self, out: Path, config: dict, record: dict, wall: float):
        """The fine-tuned design (``out/design``) and network (``out/weights``); returns the design."""
        from doefab.design.optimize import design_from_theta
        from doefab.fabrication.levels import levels_sha256
        from doefab.reconstruction.data import split_components, split_digest
        from doefab.reconstruction.train import run_provenance
        from doefab.reconstruction.weights import write_weights

        new = design_from_theta(self.design, self.theta.detach(), self.pname, self.sampling, history=[],
                                extra={"end_to_end": record}, device=self.device)
        new.save(out / "design")
        write_weights(out / "weights", "depth", "proposed", self.net,
                      {"design": "end-to-end", "design_levels_sha256": levels_sha256(new.levels), "arch": self.arch,
                       "training": {"end_to_end": config, "steps": record["steps"], "wall_time_s": round(wall, 1),
                                    **run_provenance(self.device)},
                       **self.sensor.entry(False),
                       "splits_sha256": split_digest("depth"), "splits_components": split_components("depth")},
                      (out / "history.csv").read_bytes())
        return new


def _start_network(design, design_dir, weights_dir, sensor):
    """(network, its architecture record, where it started): the one trained for the design in ``weights_dir``
    (refused if trained for another sensor's noise), or a fresh one."""
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.models import build_model, default_arch

    if weights_dir is None:
        arch = {**default_arch("depth", "proposed"), "planes": len(design.depths)}
        return build_model("depth", "proposed", arch), arch, "a fresh network"
    rec = load_reconstructor("depth", "proposed", weights_dir, design_dir, sensor=sensor, device="cpu")
    net = build_model("depth", "proposed", rec.meta["arch"])
    net.load_state_dict(rec.model.state_dict())
    return net, rec.meta["arch"], f"the network in {weights_dir}"
