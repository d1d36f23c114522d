"""Train a reconstruction network for a design on this machine's CPU (or a GPU, ``device``), with exact resume on
the CPU (on a GPU a resumed run continues from its checkpoint, not necessarily bit for bit: cuDNN's backward passes
may be nondeterministic).

Every step draws its batch from the training split by sample index (``step · batch + b``), so a resumed run
sees exactly the batches an uninterrupted one would. ``conditions`` ({"train": ..., "val": ...}, e.g.
``doefab.tolerance.conditions.for_splits``) says how the captures are made — ``doefab train`` uses each split's
honest conditions (fabricated parts' PSFs, per-column crosstalk with a calibrated unmix, depth between the
network's planes) while the network is told the nominal PSF: the domain randomisation that prepares it for a
real camera; None trains on the nominal model's own captures. The loop (budget, cosine schedule, checkpoints, history, progress) is ``reconstruction.loop``; the
weights and their metadata record go to ``weights_dir`` or else the run folder ``out_dir``
(``reconstruction.weights``). The captures are made on the CPU (their noise from seeded generators, the same on every
device) and each batch moves to the device; the network, its optimiser and the PSFs it is told live there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from doefab.applications import has
from doefab._devices import resolve_device
from doefab.errors import DoefabError
from doefab.reconstruction.data import split_components, split_digest
from doefab.reconstruction.loop import run_loop, training_threads
from doefab.reconstruction.metrics import mean_metrics, metrics_for
from doefab.reconstruction.models import build_model, default_arch, loss_fn
from doefab.reconstruction.specs import get_spec, make_batch, psf_pair, training_crop
from doefab.reconstruction.weights import weights_target, write_weights
from doefab.validate import distance_record

__all__ = ["train", "fit_network", "model_inputs", "evaluate_batch", "sensor_response_for", "arch_for_design",
           "copy_matching"]


def model_inputs(task: str, pair) -> torch.Tensor | None:
    """The PSFs the network is conditioned on: the coded PSF per band, [1, C, K, K] (hyperspectral); the coded
    then the uncoded RGB PSF, [1, 6, K, K] (HDR: its least-squares solve uses both halves); the coded and
    uncoded PSFs of every depth plane, [2, D, 3, K, K] (depth: its cross-blur cost volume)."""
    if has(task, "depth"):
        return torch.stack([pair.coded, pair.uncoded]).to(torch.float32)
    if has(task, "highlights"):
        return torch.cat([pair.coded[0], pair.uncoded[0]])[None].to(torch.float32)
    return pair.coded[0][None].to(torch.float32)


def sensor_response_for(task: str, pair, sensor=None):
    """The [3, C] RGB response that forms a task's captures from its bands (hyperspectral), or None (RGB).
    ``sensor``: an ``imaging.sensor.Sensor`` (None: the default camera's)."""
    if not has(task, "spectral"):
        return None
    from doefab.imaging.sensor import Sensor

    return (sensor or Sensor()).rgb(pair.wavelengths)


def copy_matching(model: torch.nn.Module, task: str, variant: str, folder) -> dict:
    """Copy into ``model`` every tensor of ``folder``'s ``task``/``variant`` weights whose name and shape match
    (a warm start); returns {"from", "tensors", "of"}."""
    from doefab.reconstruction.weights import renamed_state, weights_paths

    pt, _ = weights_paths(task, variant, folder)
    if not pt.is_file():
        return {"from": str(pt), "tensors": 0, "of": len(model.state_dict()), "why": "no such weights"}
    try:
        src = renamed_state(torch.load(pt, weights_only=True, map_location="cpu"))
    except Exception as exc:  # noqa: BLE001 - a damaged file only loses the warm start
        return {"from": str(pt), "tensors": 0, "of": len(model.state_dict()), "why": exc.__class__.__name__}
    own = model.state_dict()
    take = {k: v for k, v in src.items() if k in own and own[k].shape == v.shape}
    model.load_state_dict(take, strict=False)
    return {"from": str(pt), "tensors": len(take), "of": len(own)}


def arch_for_design(task: str, pair, sensor=None) -> dict:
    """The architecture entries a design fixes: the depth planes (one cost-volume channel each) and the depth
    range (outputs up to 1.2× the farthest plane); a spectral design's bands (one output each) and, for a
    ``sensor`` whose response is not the default camera's, that response on the bands (its inverses are built
    from it). ``pair``: the design's ``PSFPair`` (its ``wavelengths`` and ``depths``, metres)."""
    return arch_for_bands(task, pair.wavelengths, pair.depths, sensor)


def arch_for_bands(task: str, wavelengths, depths, sensor=None) -> dict:
    """``arch_for_design`` from a design's bands and planes (metres) alone, before any PSF is computed.

    Example: ``arch_for_bands("depth", [656e-9, 589e-9, 486e-9], [1.0, 2.0, 5.0])`` →
    ``{"planes": 3, "max_depth_m": 6.0}``."""
    if has(task, "depth"):
        far = max(z for z in depths if np.isfinite(z))
        return {"planes": len(depths), "max_depth_m": round(1.2 * far, 6)}
    if has(task, "spectral"):
        from doefab.reconstruction.data import HS_WAVELENGTHS_M

        lams = [float(w) for w in wavelengths]
        same = len(lams) == len(HS_WAVELENGTHS_M) and np.allclose(lams, HS_WAVELENGTHS_M, rtol=0, atol=1e-12)
        out = {} if same else {"wavelengths_m": lams}
        if sensor is not None and not sensor.has_default_response():
            out["response"] = sensor.rgb(lams).astype(float).tolist()
        return out
    return {}


def evaluate_batch(task: str, model, coded, uncoded, target, psf, chunk: int = 4) -> dict:
    """Mean of the task's metrics over a batch (model in eval mode, no gradients; each chunk and ``psf`` on the
    model's device, ``psf``'s where the model holds no tensors)."""
    model.eval()
    rows = []
    dev = next(iter(model.parameters()), next(iter(model.buffers()), psf)).device
    psf = psf.to(dev)
    with torch.no_grad():
        for i in range(0, coded.shape[0], chunk):
            pred = model(coded[i:i + chunk].to(dev), uncoded[i:i + chunk].to(dev), psf)
            for p, t in zip(pred.cpu().numpy(), target[i:i + chunk].numpy()):
                rows.append(metrics_for(task, p, t))
    model.train()
    return mean_metrics(rows)


@training_threads
def train(task: str, variant: str = "proposed", minutes: float = 10.0, out_dir: str | Path = "out/train",
          resume: bool = False, seed: int = 0, batch: int = 4, crop: int | None = None, val_images: int = 8,
          val_every: int = 50, lr: float = 1e-3, weights_dir: str | Path | None = None, arch: dict | None = None,
          progress: bool = True, command: str = "", max_steps: int | None = None, design=None,
          schedule: str = "cosine", replace_shipped: bool = False, conditions: dict | None = None,
          warm_start: str | Path | None = None, sensor=None, device=None) -> dict:
    """Train ``task``/``variant`` for ``minutes`` of wall time (or ``max_steps`` steps, whichever comes first);
    returns the metadata record written (``weights_path``: where the weights went). ``design``: a design folder
    other than the committed one. Weights go to ``weights_dir`` or else ``out_dir``; the shipped ones are
    replaced only with ``replace_shipped=True``. ``conditions``: {"train": ..., "val": ...} capture conditions
    (None: the nominal model's own captures). ``warm_start``: a weights folder (e.g. ``WEIGHTS_DIR``) whose
    network of this task and variant starts the training wherever a tensor's name and shape match. ``sensor``:
    the camera's ``imaging.sensor.Sensor`` (response and noise; None: the default camera's), recorded with the
    weights. ``device``: where the network trains ("auto", "cpu", "cuda", "cuda:N"; None: the current default,
    ``doefab._devices.default_device``); a run may resume on another device."""
    from doefab.imaging.sensor import Sensor

    dev = resolve_device(device)
    spec = get_spec(task)
    weights_dir = weights_target(weights_dir, out_dir, replace_shipped, design, task, variant)
    if not (0 < minutes <= 24 * 60):
        raise DoefabError(f"minutes must be in (0, 1440], got {minutes!r}")
    crop = training_crop(task, crop)
    sensor = sensor or Sensor()
    arch = arch or default_arch(task, variant)
    out = Path(out_dir)
    config = {"task": task, "variant": variant, "seed": seed, "batch": batch, "crop": crop, "lr": lr, "arch": arch,
              "schedule": schedule, "val_images": val_images, "design": None if design is None else str(design),
              "conditions": {k: c.describe() for k, c in (conditions or {}).items()}}
    config.update(sensor.entry(has(task, "spectral")))  # none for the default sensor: old runs resume
    pair, sha = psf_pair(task, design)
    arch = {**arch, **arch_for_design(task, pair, sensor)}
    psf = model_inputs(task, pair).to(dev)
    response, noise = sensor_response_for(task, pair, sensor), sensor.noise()
    torch.manual_seed(seed)
    model = build_model(task, variant, arch)
    warm = copy_matching(model, task, variant, warm_start) if warm_start is not None and not resume else None
    model.to(dev)  # built and warm-started on the CPU: the same first weights on every device
    warm = _warm_record(Path(out_dir), warm, resume)
    steps, history, wall, final = fit_network(task, model, psf, pair, (response, noise), conditions, out, config,
                                              minutes, lr=lr, batch=batch, crop=crop, val_images=val_images,
                                              val_every=val_every, schedule=schedule, resume=resume,
                                              progress=progress, desc=f"train {task} ({variant})",
                                              max_steps=max_steps)
    record = {"design": spec.design if design is None else str(design), "design_levels_sha256": sha, "arch": arch,
              "psf": {"kernel_px": int(pair.coded.shape[-1]), "wavelengths_m": list(pair.wavelengths),
                      "depths_m": [distance_record(z) for z in pair.depths], "route": "spectral",
                      "from": f"the design's {_design_levels(task, design)}-level level map (levels.npy)"},
              "training": {"command": command, "seed": seed, "steps": steps, "batch": batch, "crop_px": crop, "lr": lr,
                           "schedule": schedule, "wall_time_s": round(wall, 1), "minutes_budget": minutes,
                           "conditions": config["conditions"] or "clean", "warm_start": warm,
                           **stopped_note(steps, max_steps, minutes), **run_provenance(dev)},
              "validation": {"images": val_images, "crop_px": crop, **final},
              **sensor.entry(has(task, "spectral")),
              "splits_sha256": split_digest(task), "splits_components": split_components(task)}
    return write_weights(weights_dir, task, variant, model, record, (out / "history.csv").read_bytes())


def stopped_note(steps: int, max_steps: int | None, minutes: float) -> dict:
    """{"stopped": why} where the time budget ended a run of counted steps before its last one (a cosine schedule
    then had not finished its decay); {} otherwise."""
    if max_steps is None or steps >= max_steps:
        return {}
    return {"stopped": f"the {minutes:g} min time budget ended the run at step {steps} of {max_steps} (raise the "
                       f"budget, --minutes, to train all the steps)"}


def run_provenance(device) -> dict:
    """What a training run's weights depend on beyond its settings: torch's thread count (the sums add in another
    order on more threads), the device, the code and the libraries' versions."""
    from doefab.reconstruction.provenance import code_version, library_versions

    return {"threads": torch.get_num_threads(), "device": str(device), "code": code_version(),
            "versions": library_versions()}


def fit_network(task: str, model, psf, pair, sensor: tuple, conditions, out: Path, config: dict, minutes: float, *,
                lr: float, batch: int, crop: int, val_images: int, val_every: int, schedule: str = "cosine",
                resume: bool = False, progress: bool = True, desc: str = "train", max_steps: int | None = None,
                validate_first: bool = False) -> tuple[int, list, float, dict]:
    """Train ``model`` (told ``psf``, on its device) with Adam on ``task``'s training scenes, captured through
    ``pair`` (or ``conditions``' parts: {"train", "val"}, None: clean) with ``sensor`` = (response, noise), in the
    loop of ``reconstruction.loop`` (``config``: what a resume must share); returns (steps, history, seconds, the
    final validation metrics on ``val_images`` scenes)."""
    response, noise = sensor
    cond = conditions or {"train": None, "val": None}
    dev, metric = psf.device, get_spec(task).metric
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    val = make_batch(task, "val", range(val_images), crop, pair, response, noise, conditions=cond["val"])

    def step_fn(step: int) -> float:
        coded, uncoded, target = make_batch(task, "train", range(step * batch, (step + 1) * batch), crop, pair,
                                            response, noise, conditions=cond["train"])
        opt.zero_grad()
        loss = loss_fn(task, model(coded.to(dev), uncoded.to(dev), psf), target.to(dev))
        if torch.isfinite(loss):
            loss.backward()
            opt.step()
        return float(loss.detach())

    model.train()
    steps, history, wall = run_loop(out, config, minutes, step_fn,
                                    lambda: evaluate_batch(task, model, *val, psf)[metric],
                                    {"model": model, "optimizer": opt}, [(opt, lr)], schedule, metric, val_every,
                                    resume, progress, desc, max_steps, validate_first=validate_first)
    return steps, history, wall, evaluate_batch(task, model, *val, psf)


def _design_levels(task: str, design) -> int:
    """The number of levels L of the design the networks are trained for (the committed one: 16)."""
    from doefab.design.design import Design
    from doefab.reconstruction.specs import design_dir

    return Design.load(design or design_dir(task)).n_levels


def _warm_record(out: Path, warm: dict | None, resume: bool) -> dict | None:
    """The warm start of a fresh run, kept in ``out/warm_start.json``; a resumed run reads the record of the run
    it continues (its weights started there, not from scratch)."""
    from doefab.io import read_json

    path = out / "warm_start.json"
    if resume:
        try:
            return read_json(path)
        except (OSError, ValueError):
            return None
    from doefab.io import atomic_write_json

    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(path, warm)
    return warm
