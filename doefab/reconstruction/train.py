"""Train a reconstruction network for a committed design on this machine's CPU, with exact resume.

Every step draws its batch from the training split by sample index (``step · batch + b``), so a resumed run
sees exactly the batches an uninterrupted one would; the model, the optimiser and the step are checkpointed
(atomically, loaded with ``weights_only=True``). ``history.csv`` logs step, wall time, loss and the validation
metric; a progress bar shows the loss and the metric. The learning rate follows a cosine decay over the
*wall-time* budget (``schedule="cosine"``, to 5 % of ``lr`` at the end): a fixed-minutes run cannot know its
step count in advance, and a network trained for minutes gains most from annealing at the end (``"constant"``
turns it off); a resumed run continues the schedule from the checkpoint's elapsed time, and a larger budget on
resume stretches it (the rate rises again). The finished weights and their metadata record
(design ``levels_sha256``, PSF settings, training command, seed, wall time, validation metrics, the weights'
SHA-256) are written atomically beside each other, into ``weights_dir`` or else the run folder ``out_dir``;
the shipped weights (``doefab/weights``) are replaced only when ``replace_shipped=True`` asks for it.
"""

from __future__ import annotations

import hashlib
import io
import json
import time
from pathlib import Path

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.io import atomic_write_bytes, atomic_write_json, atomic_write_text
from doefab.reconstruction.metrics import mean_metrics, metrics_for
from doefab.reconstruction.models import build_model, default_arch, loss_fn
from doefab.reconstruction.specs import get_spec, make_batch, psf_pair

__all__ = ["train", "lr_factor", "SCHEDULES", "WEIGHTS_DIR", "weights_paths", "history_path", "model_inputs",
           "evaluate_batch", "sensor_response_for", "weights_target", "is_shipped"]

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
SCHEDULES = ("cosine", "constant")
LR_FLOOR = 0.05


def lr_factor(schedule: str, fraction: float) -> float:
    """Learning-rate multiplier after ``fraction`` of the wall-time budget: 1 throughout for ``"constant"``;
    for ``"cosine"`` from 1 down to ``LR_FLOOR`` along half a cosine, and ``LR_FLOOR`` past the budget."""
    if schedule == "constant":
        return 1.0
    if schedule != "cosine":
        raise DoefabError(f"unknown learning-rate schedule {schedule!r}: use one of {', '.join(SCHEDULES)}")
    f = min(max(float(fraction), 0.0), 1.0)
    # a Python float, not numpy's: the optimiser state goes into checkpoints loaded with weights_only=True
    return float(LR_FLOOR + (1.0 - LR_FLOOR) * 0.5 * (1.0 + np.cos(np.pi * f)))


def weights_paths(task: str, variant: str, folder: str | Path | None = None) -> tuple[Path, Path]:
    base = Path(folder) if folder is not None else WEIGHTS_DIR
    return base / f"{task}_{variant}.pt", base / f"{task}_{variant}.json"


def is_shipped(folder: str | Path | None) -> bool:
    """Whether ``folder`` (None: the default) is the package's shipped weights folder."""
    return folder is None or Path(folder).resolve() == WEIGHTS_DIR.resolve()


def weights_target(weights_dir: str | Path | None, out_dir: str | Path, replace_shipped: bool = False,
                   design=None) -> Path:
    """Where training writes its weights: ``weights_dir``, else the run folder ``out_dir``; the shipped folder
    only with ``replace_shipped`` (and only for the committed design). Checked before any work."""
    if replace_shipped:
        if design is not None:
            raise DoefabError("--replace-shipped: the shipped weights belong to the committed design; a network "
                              "for --design goes to --out or --weights-dir")
        if weights_dir is not None and not is_shipped(weights_dir):
            raise DoefabError(f"--replace-shipped writes to {WEIGHTS_DIR}; --weights-dir {weights_dir} names "
                              f"another folder: give one of them")
        return WEIGHTS_DIR
    target = Path(out_dir if weights_dir is None else weights_dir)
    if is_shipped(target):
        raise DoefabError(f"--weights-dir {target} is the shipped weights folder: pass --replace-shipped to replace "
                          f"the shipped networks (or give another folder)")
    if target.exists() and not target.is_dir():
        raise DoefabError(f"--weights-dir {target} is a file: give a folder")
    return target


def history_path(task: str, variant: str, folder: str | Path | None = None) -> Path:
    """The validation curve shipped beside the weights (the report's "training time" plot)."""
    return weights_paths(task, variant, folder)[0].with_name(f"{task}_{variant}_history.csv")


def model_inputs(task: str, pair) -> torch.Tensor | None:
    """The PSFs the network is conditioned on: the coded PSF per band, [1, C, K, K] (hyperspectral); the coded
    then the uncoded RGB PSF, [1, 6, K, K] (HDR: its least-squares solve uses both halves); the coded and
    uncoded PSFs of every depth plane, [2, D, 3, K, K] (depth: its cross-blur cost volume)."""
    if task == "depth":
        return torch.stack([pair.coded, pair.uncoded]).to(torch.float32)
    if task == "hdr":
        return torch.cat([pair.coded[0], pair.uncoded[0]])[None].to(torch.float32)
    return pair.coded[0][None].to(torch.float32)


def sensor_response_for(task: str, pair):
    """The [3, C] RGB response that forms a task's captures from its bands (hyperspectral), or None (RGB)."""
    if task != "hyperspectral":
        return None
    from doefab.imaging.sensor import sensor_response

    return sensor_response(pair.wavelengths)


def evaluate_batch(task: str, model, coded, uncoded, target, psf, chunk: int = 4) -> dict:
    """Mean of the task's metrics over a batch (model in eval mode, no gradients)."""
    model.eval()
    rows = []
    with torch.no_grad():
        for i in range(0, coded.shape[0], chunk):
            pred = model(coded[i:i + chunk], uncoded[i:i + chunk], psf)
            for p, t in zip(pred.numpy(), target[i:i + chunk].numpy()):
                rows.append(metrics_for(task, p, t))
    model.train()
    return mean_metrics(rows)


def train(task: str, variant: str = "proposed", minutes: float = 10.0, out_dir: str | Path = "out/train",
          resume: bool = False, seed: int = 0, batch: int = 4, crop: int = 96, val_images: int = 8,
          val_every: int = 50, lr: float = 1e-3, weights_dir: str | Path | None = None, arch: dict | None = None,
          progress: bool = True, command: str = "", max_steps: int | None = None, design=None,
          schedule: str = "cosine", replace_shipped: bool = False) -> dict:
    """Train ``task``/``variant`` for ``minutes`` of wall time (or ``max_steps`` steps, whichever comes first);
    returns the metadata record written (``weights_path``: where the weights went). ``design``: a design folder
    other than the committed one (candidates). Weights go to ``weights_dir`` or else ``out_dir``; the shipped
    ones are replaced only with ``replace_shipped=True``."""
    from doefab.design.checkpoint import load_checkpoint, save_checkpoint

    spec = get_spec(task)
    weights_dir = weights_target(weights_dir, out_dir, replace_shipped, design)
    lr_factor(schedule, 0.0)  # an unknown schedule fails before any work
    if not (0 < minutes <= 24 * 60):
        raise DoefabError(f"minutes must be in (0, 1440], got {minutes!r}")
    if crop % 32 or crop < 64:
        raise DoefabError(f"crop must be a multiple of 32 and at least 64, got {crop}")
    torch.set_num_threads(max(1, min(2, torch.get_num_threads())))
    arch = arch or default_arch(task, variant)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ckpt = out / "checkpoint.pt"
    config = {"task": task, "variant": variant, "seed": seed, "batch": batch, "crop": crop, "lr": lr, "arch": arch,
              "schedule": schedule, "val_images": val_images, "design": None if design is None else str(design)}
    pair, sha = psf_pair(task, design)
    if arch.get("cost_volume"):  # the cost volume has one channel per depth plane of the design
        arch = {**arch, "planes": len(pair.depths)}
    psf = model_inputs(task, pair)
    response = sensor_response_for(task, pair)
    torch.manual_seed(seed)
    model = build_model(task, variant, arch)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    step, elapsed, history = 0, 0.0, []
    if resume:
        state = load_checkpoint(ckpt, {"config": config}, ignore=())  # same settings or a clear refusal
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        step, elapsed, history = int(state["step"]), float(state["elapsed"]), [list(r) for r in state["history"]]
    val = make_batch(task, "val", range(val_images), crop, pair, response)
    budget = minutes * 60.0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=int(budget), initial=int(min(elapsed, budget)), desc=f"train {task} ({variant})", unit="s")
    t0 = time.perf_counter() - elapsed
    last_metric = history[-1][3] if history else float("nan")

    def save(step_now: int) -> None:
        save_checkpoint(ckpt, {"config": json.dumps({"config": config}, sort_keys=True), "theta": torch.zeros(1),
                               "model": model.state_dict(), "optimizer": opt.state_dict(), "step": step_now,
                               "elapsed": float(time.perf_counter() - t0), "history": history,
                               "generator": torch.get_rng_state()})
        lines = ["step,wall_time_s,loss,val_" + spec.metric] + [",".join(f"{v:.6g}" for v in r) for r in history]
        atomic_write_text(out / "history.csv", "\n".join(lines) + "\n")

    model.train()
    try:
        while time.perf_counter() - t0 < budget and (max_steps is None or step < max_steps):
            coded, uncoded, target = make_batch(task, "train", range(step * batch, (step + 1) * batch), crop, pair,
                                                response)
            for group in opt.param_groups:
                group["lr"] = lr * lr_factor(schedule, (time.perf_counter() - t0) / budget)
            opt.zero_grad()
            loss = loss_fn(task, model(coded, uncoded, psf), target)
            if not torch.isfinite(loss):
                raise DoefabError(f"training loss became {float(loss)} at step {step}; the last checkpoint is kept "
                                  f"in {ckpt} (lower the learning rate)")
            loss.backward()
            opt.step()
            step += 1
            row_metric = last_metric
            if step % val_every == 0:
                last_metric = evaluate_batch(task, model, *val, psf)[spec.metric]
                row_metric = last_metric
            history.append([step, round(time.perf_counter() - t0, 2), float(loss.detach()), row_metric])
            if step % val_every == 0:
                save(step)
            if bar is not None:
                bar.n = int(min(time.perf_counter() - t0, budget))
                bar.set_postfix(step=step, loss=f"{float(loss.detach()):.4f}", **{spec.metric: f"{last_metric:.4g}"})
                bar.refresh()
    finally:
        if bar is not None:
            bar.close()
    final = evaluate_batch(task, model, *val, psf)
    history.append([step, round(time.perf_counter() - t0, 2), history[-1][2] if history else float("nan"),
                    final[spec.metric]])
    save(step)
    buf = io.BytesIO()
    torch.save(model.state_dict(), buf)
    data = buf.getvalue()
    pt, meta_path = weights_paths(task, variant, weights_dir)
    meta = {"format": "doefab weights 1", "task": task, "variant": variant,
            "design": spec.design if design is None else str(design),
            "design_levels_sha256": sha, "arch": arch,
            "psf": {"kernel_px": spec.kernel, "wavelengths_m": list(pair.wavelengths),
                    "depths_m": [z if np.isfinite(z) else "inf" for z in pair.depths], "route": "spectral",
                    "from": "the committed 16-level level map (levels.npy)"},
            "training": {"command": command, "seed": seed, "steps": step, "batch": batch, "crop_px": crop, "lr": lr,
                         "schedule": schedule,
                         "wall_time_s": round(time.perf_counter() - t0, 1), "minutes_budget": minutes},
            "validation": {"images": val_images, "crop_px": crop, **final},
            "weights_sha256": hashlib.sha256(data).hexdigest(), "weights_file": pt.name}
    atomic_write_bytes(pt, data)
    atomic_write_json(meta_path, meta)
    atomic_write_bytes(history_path(task, variant, weights_dir), (out / "history.csv").read_bytes())
    return {**meta, "weights_path": str(pt.resolve())}
