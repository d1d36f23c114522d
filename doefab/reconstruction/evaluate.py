"""The paper's Tables 1–3: every variant's network on the same held-out scenes, under the conditions a real camera
makes (``conditions``: ``doefab.tolerance.conditions.honest`` — a fabricated part's PSF, per-column crosstalk
unmixed with a noisy calibration, depth between the network's planes — while the network is told the nominal
PSF; ``doefab evaluate``'s default) or the nominal model's own captures (None). With ``psf=`` (``doefab evaluate
--psf``) the networks are told a given pair instead — a measured part's — and the scenes are captured through that
pair (``conditions.measured``) or through ``capture_psf`` (a model fitted to it, say; alone: the networks told
their nominal pair).

Splits (``SPLITS``): ``val`` for every choice made along the way, ``test`` for the published tables (every
committed read of it is listed in ``benchmarks/results/test_split_reads.md``; a user's read is not logged) and
``final``, the final test set, made after every earlier read and read only when asked for by name; each read of
it appends a line to ``final_split_reads.md`` in the output folder (``FINAL_LEDGER``) before its first scene is
scored; ``real``, the measured-data validation set (``realdata``: scenes made of measured data doefab did not
make, never trained on), under the same conditions.

An evaluation runs torch on one thread (``THREADS``; restored after): a reduction split over threads adds in
another order, and the HDR solve's iterations carry that difference to tenths of a dB, so a table is reproducible
to its printed digits only at a fixed thread count.

``evaluate(task, out_dir)`` writes ``metrics.json`` (``{"task", "split", "seed", "conditions", "images",
"size_px", "threads", "versions": {library: version}, "code", "parts_sha256", "rows": {variant: means}, "units":
{metric: its unit, "1" where dimensionless}, "scales": {metric: what it is relative to, where not a plain ratio},
"by_light": {"in-library" | "out-of-library": {variant: means}}, "weights": {variant: {"sha256", "steps", ...,
"splits"}}, "per_image": {"light", "rows": {variant: [metrics of each scene]}}, "psf": {"told",
"captured_through"}}``; the light groups for hyperspectral; ``psf`` with a given pair: each pair's file,
SHA-256, provenance, bands, planes and window) and ``examples.png`` (inputs, each variant's output, ground truth,
error map).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import torch

from doefab.applications import application, has
from doefab.errors import DoefabError
from doefab.io import atomic_write_json, atomic_write_text
from doefab.reconstruction.data import CONTENT_COMPONENTS, SPLIT_SEEDS, split_components, split_digest, split_digest_v1
from doefab.reconstruction.loader import load_reconstructor
from doefab.reconstruction.metrics import mean_metrics, metrics_for
from doefab.reconstruction.loop import torch_threads
from doefab.reconstruction.networks import VARIANTS
from doefab.reconstruction.provenance import code_version, library_versions
from doefab.reconstruction.partfinetune import check_capture, fit_to_network, pair_record
from doefab.reconstruction.specs import make_batch, psf_pair

__all__ = ["evaluate", "SPLITS", "THREADS", "FINAL_LEDGER", "one_thread", "library_versions", "code_version"]

SPLITS = ("val", "test", "final", "real")
THREADS = 1
FINAL_LEDGER = "final_split_reads.md"


def evaluate(task: str, out_dir: str | Path, images: int = 16, size: int = 256, weights_dir=None,
             progress: bool = True, design=None, variants=VARIANTS, conditions=None, split: str = "test",
             other_design: bool = False, sensor=None, psf=None, capture_psf=None, psf_records=None) -> dict:
    """``conditions``: the split's capture conditions (``doefab.tolerance.conditions``; None: clean).
    ``sensor``: the camera's ``imaging.sensor.Sensor`` that makes the captures (response, noise; None: the
    default camera's). ``other_design``: evaluate networks trained for another design or sensor on these
    captures (they are told ``design``'s PSFs); the result says so. ``split``: one of ``SPLITS``.
    ``psf``: a PSF pair the networks are told instead of their design's (a measured part's, checked by
    ``partfinetune.fit_to_network``); the captures are rendered through ``capture_psf`` (default ``psf``; alone:
    a part the networks are not told of) where ``conditions`` give no part of their own. ``psf_records``: what
    identifies them in ``metrics.json`` (``{"told", "captured_through"}``, ``partfinetune.pair_record``)."""
    from doefab.imaging.sensor import Sensor

    if split not in SPLITS:
        raise DoefabError(f"split {split!r} is not one of {', '.join(SPLITS)}: val for choices along the way, test "
                          f"for the tables, final for the final test set, real for the measured-data validation set")
    out = Path(out_dir)
    sensor = sensor or Sensor()
    recs = {v: load_reconstructor(task, v, weights_dir, design, other_design, sensor)
            for v in variants}  # refuse first
    told = None if psf is None else fit_to_network(psf, next(iter(recs.values())).pair, task)
    if capture_psf is not None:
        check_capture(capture_psf, next(iter(recs.values())).pair, "capture_psf")
    if split == "real":
        from doefab.reconstruction.data import real_components
        from doefab.reconstruction.realdata import check_side

        check_side(task, size, next(iter(recs.values())).pair.coded.shape[-1] // 2)
    components = split_components(task)
    weights = {v: _weights_entry(r.meta, task, components) for v, r in recs.items()}
    cond = conditions.describe() if conditions is not None else {"name": "clean"}
    code = code_version()  # two git calls: once for the ledger and the result
    if split == "final":  # logged before a scene is scored: an interrupted or failed read is a read too
        out.mkdir(parents=True, exist_ok=True)
        _log_final_read(out / FINAL_LEDGER, {"task": task, "images": images, "size_px": size, "conditions": cond,
                                             "code": code, "weights": weights})
    with one_thread():
        rows, kinds, example = _score(task, split, images, size, recs, design, sensor, conditions, progress, told,
                                      capture_psf if capture_psf is not None else psf)
    result = {"task": task, "split": split, "images": images, "seed": SPLIT_SEEDS[split], "size_px": size,
              "conditions": cond,
              "parts_sha256": _parts_sha256(conditions),
              "noise": f"Poisson–Gaussian, {sensor.describe(with_response=False)}" if sensor.entry(False)
              else "default (Poisson–Gaussian)", **sensor.entry(has(task, "spectral")),
              "threads": THREADS, "versions": library_versions(), "code": code,
              "rows": {v: mean_metrics(rs) for v, rs in rows.items()},
              # "1": dimensionless; "scales" says what a value that is not a plain ratio is relative to
              "units": {m.name: m.unit or "1" for m in application(task).metrics},
              "scales": {m.name: m.scale for m in application(task).metrics if m.scale},
              "weights": weights}
    if psf is not None or capture_psf is not None:
        result["psf"] = psf_records or {
            "told": "the design's nominal pair" if psf is None else pair_record(psf),
            "captured_through": pair_record(capture_psf if capture_psf is not None else psf)}
    if split == "real":
        result["real_sha256"] = real_components()  # what made the measured set's scenes
    result["per_image"] = {"light": kinds if has(task, "spectral") else None, "rows": rows}  # for intervals
    if has(task, "spectral"):
        result["by_light"] = {k: {v: mean_metrics([r for r, kk in zip(rs, kinds) if kk == k]) for v, rs in rows.items()}
                              for k in ("in-library", "out-of-library") if k in kinds}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "metrics.json", result)
    _figure(out / "examples.png", task, split, *example)
    return result


def _score(task, split, images, size, recs, design, sensor, cond, progress, told=None,
           render=None, indices=None) -> tuple[dict, list, tuple]:
    """Every variant's metrics on each of the split's ``images`` scenes (``indices``: only those of them; rendered
    through ``render``, default the design's pair, where ``cond`` gives no part; the networks told ``told``,
    default their own pair), the scenes' kinds of light and the first scene's (coded, uncoded, target,
    {variant: output}) for the figure."""
    from doefab.reconstruction.spectra import light_kind
    from doefab.reconstruction.train import sensor_response_for

    pair, _ = psf_pair(task, design)
    response = sensor_response_for(task, pair, sensor)
    pair = render if render is not None else pair
    rows = {v: [] for v in recs}
    kinds, example = [], None
    it = range(images) if indices is None else indices
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"evaluate {task} ({cond.name if cond else 'clean'}, {split})", unit="image")
    for i in it:
        coded, uncoded, target = make_batch(task, split, [i], size, pair, response, sensor.noise(), conditions=cond,
                                            images=images)  # scene i's crop at its own place across the sensor
        kinds.append(light_kind(split, i))
        preds = {}
        for v, rec in recs.items():
            p = rec(coded[0], uncoded[0], psf=told)  # told the nominal PSF (or told), whatever made the captures
            preds[v] = p.numpy() if isinstance(p, torch.Tensor) else p
            rows[v].append(metrics_for(task, preds[v], target[0].numpy()))
        if example is None:
            example = (coded[0].numpy(), uncoded[0].numpy(), target[0].numpy(), preds)
    return rows, kinds, example


def one_thread():
    """torch on ``THREADS`` thread(s) inside the block, its earlier thread count restored after
    (``loop.torch_threads``)."""
    return torch_threads(THREADS)


def _parts_sha256(cond) -> str | None:
    """SHA-256 of the fabricated parts' PSFs the captures were made through (None: the nominal PSF)."""
    parts = getattr(cond, "parts", None)
    if not parts:
        return None
    h = hashlib.sha256()
    for pair in parts:
        for t in (pair.coded, pair.uncoded):
            h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def _weights_entry(meta: dict, task: str, components: dict) -> dict:
    """What identifies a network and how it was trained, for ``metrics.json``."""
    return {"sha256": meta["weights_sha256"], "steps": meta["training"]["steps"],
            "wall_time_s": meta["training"]["wall_time_s"],
            "lr_schedule": meta["training"].get("schedule", "constant"),
            "trained_under": _trained_under(meta),
            "for_this_design": not meta.get("other_design", False),
            **({"for_this_sensor": False} if meta.get("other_sensor") else {}),
            "splits": _splits_state(meta, task, components)}


def _splits_state(meta: dict, task: str, components: dict) -> str:
    """Whether a network was trained on the scenes this evaluation draws from: the same split definition, the same
    content made by other code or files, or another split definition."""
    got, theirs = meta.get("splits_sha256"), meta.get("splits_components")
    if got is None:
        return "not recorded (trained before the weights named their splits)"
    if got == split_digest(task, components):
        return "the same splits"
    if isinstance(theirs, dict):
        differ = [k for k in components if theirs.get(k) != components[k]]
        if not set(differ) & set(CONTENT_COMPONENTS):
            return f"the same split content, made by other code or files since training ({', '.join(differ)})"
        return f"ANOTHER split definition ({', '.join(differ)}): the test scenes may hold training content"
    if got == split_digest_v1(task):
        return ("the same photographs, seeds and spectra by name (recorded before the weights named the "
                "photographs' pixels, the scene generator's code, the light library and the fabricated parts)")
    return "ANOTHER split definition: the test scenes may hold training content"


def _log_final_read(path: Path, result: dict) -> None:
    """Append this read of the final test set to the output folder's ledger (a Markdown table)."""
    import datetime

    head = "| date (UTC) | code | task | what was read |\n| --- | --- | --- | --- |\n"
    text = path.read_text() if path.is_file() else head
    cond = result["conditions"]
    parts = f", {cond['parts']} fabricated parts" if cond.get("parts") else ""
    nets = ", ".join(f"{v} (weights {w['sha256'][:12]})" for v, w in result["weights"].items())
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
    line = (f"| {when} | {result['code']} | {result['task']} | {result['images']} scenes of {result['size_px']}² px, "
            f"{cond['name']} captures{parts}; {nets} |\n")
    atomic_write_text(path, text + line)


def _trained_under(meta: dict) -> str:
    c = meta.get("training", {}).get("conditions")
    return c.get("train", {}).get("name", "clean") if isinstance(c, dict) else "clean"


def _show(task, arr):
    """An image for display: HDR tone-mapped (log), spectra as their band mean, depth as is."""
    if has(task, "highlights"):
        return np.clip(np.log1p(np.moveaxis(arr, 0, -1)) / np.log1p(256.0), 0, 1)
    if has(task, "spectral"):
        return arr.mean(axis=0)
    return arr


def _figure(path: Path, task: str, split: str, coded, uncoded, target, preds) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("coded capture", np.moveaxis(coded, 0, -1) ** (1 / 2.2), None),
              ("uncoded capture", np.moveaxis(uncoded, 0, -1) ** (1 / 2.2), None)]
    unit = application(task).image_unit
    for v, p in preds.items():
        panels.append((f"{v.replace('_', '-')} output", _show(task, p), unit))
    panels.append(("ground truth", _show(task, target), unit))
    ref = "proposed" if "proposed" in preds else next(iter(preds))
    err = np.abs(preds[ref] - target)
    err = err.mean(axis=0) if err.ndim == 3 else err
    panels.append((f"|{ref.replace('_', '-')} − truth|", err, application(task).error_unit))
    fig, axes = plt.subplots(2, 4, figsize=(13, 6.6), layout="constrained")
    for ax, (title, img, cb) in zip(axes.flat, panels):
        kw = {"cmap": "viridis"} if img.ndim == 2 else {}
        if has(task, "depth") and cb == "depth (m)":
            kw.update(vmin=1.0, vmax=5.0)
        im = ax.imshow(np.clip(img, 0, None) if img.ndim == 3 else img, **kw)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x (pixels)", fontsize=7)
        ax.set_ylabel("y (pixels)", fontsize=7)
        ax.tick_params(labelsize=6)
        if img.ndim == 2:
            c = fig.colorbar(im, ax=ax, shrink=0.8)
            c.set_label(cb, fontsize=7)
            c.ax.tick_params(labelsize=6)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    fig.suptitle(f"{task}: a held-out scene of the {split} split", fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)
