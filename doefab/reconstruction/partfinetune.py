"""Networks for one fabricated part: a PSF pair (a measured ``psf_pair.npz``, or a model fitted to one) checked
against a network's design, told to the network, and a network-only fine-tune on captures made through it.

``fit_to_network(pair, network_pair, task)`` refuses a pair of other bands, depth planes or sensor pitch than the
network's design (naming the fix) and brings its PSF window to the network's (centred: cropped, or padded with
zeros — the light a recorded window did not hold is taken as none). ``finetune_on_pair`` warm-starts the task's
proposed network (the shipped one, or ``weights_dir``'s), tells it the pair and trains it on captures rendered
through the pair (or ``capture_pair``; ``conditions`` add the camera's crosstalk), with the DOE untouched. It
reuses ``reconstruction.loop`` (wall-time budget, cosine schedule, checkpoints that resume exactly,
``history.csv``, progress) and writes ``out/weights/`` in the layout ``load_reconstructor`` reads.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import torch

from doefab.applications import has
from doefab.errors import DoefabError
from doefab.optics.psf import PSFPair, describe_bands
from doefab.reconstruction.loop import training_threads
from doefab.validate import distance_record

__all__ = ["fit_to_network", "check_capture", "pair_record", "finetune_on_pair"]


def _planes(depths) -> str:
    return ", ".join("inf" if not np.isfinite(z) else f"{z:g}" for z in depths) + " m"


def _system(pair: PSFPair, network_pair: PSFPair) -> list[str]:
    return [d.replace("this pair", "the network") for d in network_pair.system_differences(pair)]


def check_capture(pair: PSFPair, network_pair: PSFPair, flag: str = "--capture-psf") -> None:
    """Refuse (naming ``flag``) a pair to render captures through whose bands or sensor pitch (camera) differ
    from the network's: those captures would be another camera's. Its planes and window may differ (a model
    fitted at finer planes)."""
    bad = _system(pair, network_pair)
    if bad:
        raise DoefabError(f"{flag}: the PSF pair is for {'; '.join(bad)}: captures for this network are rendered "
                          f"through a pair of its {describe_bands(network_pair.wavelengths)} on "
                          f"{network_pair.sensor_pitch * 1e6:.4g} µm pixels; give such a pair (or leave {flag} out)")


def fit_to_network(pair: PSFPair, network_pair: PSFPair, task: str, flag: str = "--psf") -> PSFPair:
    """``pair`` as the ``task`` network trained on ``network_pair`` takes it: the same bands, depth planes and
    sensor pitch (else one DoefabError naming ``flag``, what differs and the fix), its window cropped or
    zero-padded about the chief-ray pixel (K//2, K//2) to the network's K."""
    problems = _system(pair, network_pair)
    mine, theirs = tuple(network_pair.depths), tuple(pair.depths)
    if len(mine) != len(theirs) or not np.allclose(theirs, mine, rtol=1e-6, atol=0.0):
        problems.append(f"depth planes {_planes(theirs)} (the network: {_planes(mine)})")
    if problems:
        raise DoefabError(
            f"{flag}: the PSF pair is for {'; '.join(problems)}: the {task} network takes its design's "
            f"{describe_bands(network_pair.wavelengths)} at planes {_planes(mine)} on "
            f"{network_pair.sensor_pitch * 1e6:.4g} µm pixels; record (doefab calibrate) those bands and planes, "
            f"pass doefab diagnose's psf_pair_fitted.npz (every band and plane of the design), or give "
            f"--design/--weights-dir of networks trained for the system the pair was measured on")
    k, want = pair.coded.shape[-1], network_pair.coded.shape[-1]
    lo = want // 2 - k // 2  # before the centre; negative: cropped
    hi = (want - 1 - want // 2) - (k - 1 - k // 2)  # after it
    halves = [torch.nn.functional.pad(pair[h].float(), (lo, hi, lo, hi)) for h in ("coded", "uncoded")]
    return PSFPair(*halves, tuple(pair.wavelengths), tuple(pair.depths), pair.sensor_pitch, camera=pair.camera,
                   provenance=getattr(pair, "provenance", None))


def pair_record(pair: PSFPair, path: str | Path | None = None) -> dict:
    """What identifies a PSF pair in a record: its file and the file's SHA-256 (when read from one), its provenance
    (``psf_pair.npz``'s), bands, planes and window."""
    out = {"file": None, "sha256": None}
    if path is not None:
        out = {"file": str(Path(path).resolve()), "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()}
    return {**out, "provenance": getattr(pair, "provenance", None), "wavelengths_m": [float(w) for w in
            pair.wavelengths], "depths_m": [distance_record(z) for z in pair.depths],
            "kernel_px": int(pair.coded.shape[-1])}


def _tensor_sha256(pair: PSFPair) -> str:
    h = hashlib.sha256()
    for t in (pair.coded, pair.uncoded):
        h.update(t.detach().cpu().float().contiguous().numpy().tobytes())
    return h.hexdigest()


@training_threads
def finetune_on_pair(task: str, pair: PSFPair, out_dir, minutes: float = 5.0, *, capture_pair: PSFPair | None = None,
                     conditions: dict | None = None, weights_dir=None, design=None, lr: float = 2e-4, batch: int = 4,
                     crop: int | None = None, val_images: int = 8, val_every: int = 20, seed: int = 0,
                     resume: bool = False, progress: bool = True, max_steps: int | None = None, sensor=None,
                     device=None, records: dict | None = None, command: str = "") -> dict:
    """Fine-tune the ``task`` proposed network of ``weights_dir`` (None: the shipped one; ``design``: the design
    folder it was trained for, None: the committed one) on ``pair`` for ``minutes`` of wall time (or ``max_steps``).

    The network is told ``pair`` (``fit_to_network``); the training and validation captures are rendered through
    ``capture_pair`` (default ``pair``: the measured part is the truth), or through ``conditions`` ({"train",
    "val"}: e.g. ``tolerance.conditions.measured``, which adds the camera's crosstalk). Only the network's weights
    change. Writes ``out_dir/weights/{task}_proposed.pt`` with its record (the pair's ``records``: {"told",
    "captured_through"} of ``pair_record``), ``history.csv`` (validation metric against wall time) and
    ``checkpoint.pt``; ``resume`` continues it exactly. Returns a summary (steps, seconds, the validation metric
    before and after, the weights' path). ``sensor``: the camera's ``imaging.sensor.Sensor`` (None: the default
    one; a network trained for another is refused). ``device``: where the network trains."""
    from doefab._devices import resolve_device
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.models import build_model
    from doefab.reconstruction.specs import get_spec, training_crop
    from doefab.reconstruction.train import (fit_network, model_inputs, run_provenance, sensor_response_for,
                                               stopped_note)
    from doefab.reconstruction.weights import weights_target, write_weights

    if not 0 < minutes <= 24 * 60:
        raise DoefabError(f"minutes must be in (0, 1440], got {minutes!r}")
    spec, crop, sensor, dev = get_spec(task), training_crop(task, crop), sensor or Sensor(), resolve_device(device)
    out = Path(out_dir)
    target = weights_target(out / "weights", out, task=task, variant="proposed")  # never over files not doefab's
    start = load_reconstructor(task, "proposed", weights_dir, design, sensor=sensor, device="cpu")
    told = fit_to_network(pair, start.pair, task)
    render = capture_pair if capture_pair is not None else pair
    check_capture(render, start.pair, "capture_pair")
    torch.manual_seed(seed)
    model = build_model(task, "proposed", start.meta["arch"])
    model.load_state_dict(start.model.state_dict())  # the warm start (a resumed run's checkpoint replaces it)
    model.to(dev)
    psf = model_inputs(task, told).to(dev)
    response, noise = sensor_response_for(task, start.pair, sensor), sensor.noise()
    records = records or {"told": pair_record(pair), "captured_through": pair_record(render)}
    config = {"mode": "network only, on a given PSF pair", "task": task, "seed": seed, "batch": batch, "crop": crop,
              "lr": lr, "val_images": val_images, "start_weights_sha256": start.meta["weights_sha256"],
              "told_sha256": _tensor_sha256(told), "captured_sha256": _tensor_sha256(render),
              "conditions": {k: c.describe() for k, c in (conditions or {}).items() if c is not None},
              **sensor.entry(has(task, "spectral"))}
    steps, history, wall, final = fit_network(task, model, psf, render, (response, noise), conditions, out, config,
                                              minutes, lr=lr, batch=batch, crop=crop, val_images=val_images,
                                              val_every=val_every, resume=resume, progress=progress,
                                              desc=f"finetune {task} on the PSF pair", max_steps=max_steps,
                                              validate_first=True)
    meta = _record(start.meta, config, records, steps, wall, minutes, command, val_images, crop, final)
    meta["training"].update(**stopped_note(steps, max_steps, minutes), **run_provenance(dev))
    written = write_weights(target, task, "proposed", model, meta, (out / "history.csv").read_bytes())
    return {"steps": steps, "wall_time_s": round(wall, 1), "metric": spec.metric, "val_start": history[0][3],
            "val_end": final[spec.metric], "weights": written["weights_path"]}


def _record(start: dict, config: dict, records: dict, steps: int, wall: float, minutes: float, command: str,
            val_images: int, crop: int, final: dict) -> dict:
    """The fine-tuned network's metadata: the starting network's design, architecture and splits, and how it was
    fine-tuned (from which weights, on which pair, for how long)."""
    keep = ("design", "design_levels_sha256", "arch", "psf", "sensor", "splits_sha256", "splits_components")
    return {**{k: start[k] for k in keep if k in start},
            "training": {"command": command, "seed": config["seed"], "steps": steps, "batch": config["batch"],
                         "crop_px": crop, "lr": config["lr"], "schedule": "cosine", "wall_time_s": round(wall, 1),
                         "minutes_budget": minutes, "conditions": config["conditions"] or "clean",
                         "fine_tune": {"mode": "network only: the DOE is untouched",
                                       "start_weights_sha256": start["weights_sha256"],
                                       "start_steps": start.get("training", {}).get("steps"), **records}},
            "validation": {"images": val_images, "crop_px": crop, **final}}
