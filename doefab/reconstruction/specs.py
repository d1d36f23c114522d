"""What each reconstruction task is trained on: the committed design, its PSF pair, scenes and captures.

The networks see the PSFs of what gets fabricated: a design's L-level level map (the committed ones:
``doefab/designs/<design>.npz``, 16 levels), not the continuous heights, in a window at least as large as the
one the design was optimised in (``network_kernel``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from doefab.applications import View, application, band_problem, has
from doefab.errors import DoefabError

__all__ = ["TaskSpec", "SPECS", "get_spec", "design_dir", "psf_pair", "make_batch", "crop_margin", "render_scene",
           "check_design_task", "check_bands", "network_kernel", "training_crop"]


@dataclass(frozen=True)
class TaskSpec:
    """A view of an application's reconstruction row (``doefab.applications.Application``).  name: hdr /
    hyperspectral / depth.  design: the design task (streak / grating / half-ring).  kernel: the smallest PSF
    window (sensor pixels) used to simulate captures (``network_kernel``: a design optimised in a larger window
    keeps it).  out_channels: network outputs.  metric: the validation metric logged while training.  crop: the
    side (pixels) of the training crops."""

    name: str
    design: str
    kernel: int
    out_channels: int
    metric: str
    crop: int = 96


SPECS = View(lambda a: TaskSpec(a.name, a.design_task, a.kernel, a.out_channels, a.train_metric, a.crop))


def get_spec(task: str) -> TaskSpec:
    if task not in SPECS:
        raise DoefabError(f"unknown reconstruction task {task!r}: choose one of {sorted(SPECS)}")
    return SPECS[task]


def training_crop(task: str, crop: int | None = None) -> int:
    """The training crop side (pixels) for ``task``: ``crop``, or the task's own (``TaskSpec.crop``) when None;
    a DoefabError unless it is a multiple of 32 and at least 64 (the networks' input sizes)."""
    crop = get_spec(task).crop if crop is None else crop
    if crop % 32 or crop < 64:
        raise DoefabError(f"crop must be a multiple of 32 and at least 64, got {crop}")
    return crop


def check_design_task(task: str, design_task: str, where, flag: str = "task", wavelengths=None) -> None:
    """Refuse a design of another task than ``task``'s networks take (a grating design for the HDR network), and
    with ``wavelengths`` (metres) one on bands they cannot take (``check_bands``)."""
    spec = get_spec(task)
    if design_task != spec.design:
        owner = {s.design: s.name for s in SPECS.values()}.get(design_task)
        kind = f"a {owner} ({design_task})" if owner else f"a {design_task!r}"
        raise DoefabError(f"{where} is {kind} design; {flag} {task} needs a {spec.design} design")
    if wavelengths is not None:
        check_bands(task, wavelengths, where)


def check_bands(task: str, wavelengths, where) -> None:
    """Refuse a design at ``where`` on bands (metres) that ``task``'s networks cannot take
    (``applications.band_problem``: an RGB application's three, longest first; a spectral one's two or more)."""
    if problem := band_problem(task, wavelengths):
        raise DoefabError(f"{where}: {problem} (a scene's optics.wavelengths_nm)")


def design_dir(task: str) -> Path:
    """The committed design a task's networks are trained for (shipped in the package, ``design.committed``)."""
    from doefab.design.committed import committed_dir

    return committed_dir(get_spec(task).design)


def network_kernel(task: str, design_kernel: int | None) -> int:
    """The PSF window (sensor pixels, odd) the networks of ``task`` see for a design optimised in a window of
    ``design_kernel`` pixels: the task's own window, or the design's when it is larger (long streak arms, far
    grating orders of another camera are never cut off)."""
    k = max(get_spec(task).kernel, int(design_kernel or 0))
    return k if k % 2 else k + 1


@functools.lru_cache(maxsize=None)
def _pair_cached(folder: str, task: str, stamp: tuple):
    """(pair, levels_sha256) of the design in ``folder``, or (None, its task) when it is not ``task``'s."""
    from doefab.design.design import Design
    from doefab.fabrication.levels import levels_sha256
    from doefab.optics.psf import PSFPlan

    d = Design.load(folder)
    if d.task != get_spec(task).design:
        return None, d.task
    check_bands(task, d.wavelengths, folder)
    plan = PSFPlan(d.camera, d.wavelengths, d.depths, network_kernel(task, d.task_params.get("kernel_size")))
    with torch.no_grad():
        pair = plan(d.quantized_height)  # the design's own L levels
    return pair, levels_sha256(d.levels)


def psf_pair(task: str, folder: str | Path | None = None):
    """(PSFPair of the design's L-level map at ``network_kernel``, its levels_sha256) for ``task`` (cached); a
    design folder of another task is refused."""
    folder = Path(folder or design_dir(task))
    # keyed by the folder's files too: a design rewritten in the same folder is a new design
    stamp = tuple((f, (folder / f).stat().st_mtime_ns, (folder / f).stat().st_size) if (folder / f).is_file()
                  else (f, None, None) for f in ("design.json", "levels.npy"))
    pair, sha = _pair_cached(str(folder), task, stamp)
    if pair is None:
        check_design_task(task, sha, folder)
    return pair, sha


def crop_margin(task: str, pair=None) -> int:
    """Half the PSF window (pixels) a scene is generated beyond its crop: ``pair``'s window, or the task's."""
    return (pair.coded.shape[-1] if pair is not None else get_spec(task).kernel) // 2


def make_batch(task: str, split: str, indices, size: int, pair, response=None, noise="default", conditions=None,
               images: int | None = None):
    """Scenes, targets and simulated captures for sample ``indices`` of ``split``.

    Each scene is generated with a margin of half a PSF window on every side, blurred, and cropped back to
    ``size``, so the captures hold the light that enters the crop from outside it. ``conditions``
    (``reconstruction.conditions``): what the camera adds — scene i rendered through ``conditions.pair_for(i)``
    (a fabricated part's PSFs, for depth at finer planes), its views mixed by crosstalk and unmixed by a
    calibrated pipeline; default: ``pair`` and clean views; ``images``: how many scenes the crops are spread
    across on the sensor (each sees the crosstalk of its place; default ``len(indices)``). Training, evaluation
    and the tolerance study's network judge (one fabricated part's conditions) all make their captures here.
    Hyperspectral scenes are lit per ``spectra.light_kind(split, i)``.
    Returns (coded [B, 3, S, S], uncoded [B, 3, S, S], target [B, C, S, S] or depth [B, S, S]) tensors.
    """
    from doefab.imaging.crosstalk import DualPixelCrosstalk
    from doefab.imaging.sensor import noise_model
    from doefab.reconstruction.data import sample_rng

    m = crop_margin(task, pair)
    nm = noise_model(noise)
    coded, uncoded, targets = [], [], []
    t = None if response is None else torch.as_tensor(response, dtype=torch.float32)
    n = images if images is not None else (len(indices) if hasattr(indices, "__len__") else 8)
    for i in indices:
        rng = sample_rng(split, i)
        p = conditions.pair_for(i, pair) if conditions is not None else pair
        scene, target, views = render_scene(task, split, i, rng, size + 2 * m, p, t)
        xt = conditions.crosstalk_for(i, n, size, nm) if conditions is not None else None
        c_view, u_view = (xt or DualPixelCrosstalk(0.0, 0.0)).record(
            *(v[:, m:m + size, m:m + size].double().numpy() for v in views), nm, rng)
        coded.append(torch.from_numpy(c_view.astype(np.float32)))
        uncoded.append(torch.from_numpy(u_view.astype(np.float32)))
        tgt = target[m:m + size, m:m + size] if has(task, "depth") else scene[:, m:m + size, m:m + size]
        targets.append(torch.from_numpy(np.ascontiguousarray(tgt)))
    return torch.stack(coded), torch.stack(uncoded), torch.stack(targets)


def render_scene(task: str, split: str, index: int, rng, big: int, pair, response):
    """(scene, target, (coded, uncoded) clean views before noise) of one scene of side ``big``: made by the
    application's ``scene_function`` (``doefab.applications``; generated, or for split ``real`` made of measured
    data, ``realdata``), rendered through both halves of ``pair`` (at each pixel's plane where the scene has
    depth) and, with a sensor ``response``, seen in its colours; a depth target is NaN where it was not
    measured."""
    from doefab.imaging.captures import render_layers

    scene, target, masks, known = application(task).function("scene_function")(split, index, rng, big, pair)
    s = torch.from_numpy(scene)
    views = []
    for psf in (pair.coded.to(torch.float32), pair.uncoded.to(torch.float32)):
        b = render_layers(s, psf, masks, pair.depths)
        views.append(torch.einsum("rc,chw->rhw", response, b) if response is not None else b)
    if known is not None:
        target = np.where(known, target, np.float32(np.nan))
    return scene, target, views


def hdr_scene(split: str, index: int, rng, big: int, pair):
    """(radiance [3, big, big], None, None, None): an HDR scene with highlights (``scene_function`` of hdr)."""
    from doefab.reconstruction.data import hdr_sample
    from doefab.reconstruction.realdata import hdr_real_sample

    return (hdr_real_sample(rng, big) if split == "real" else hdr_sample(rng, big, split)), None, None, None


def spectral_scene(split: str, index: int, rng, big: int, pair):
    """(spectra [C, big, big] on ``pair``'s bands, None, None, None): a reflectance scene under the light
    ``spectra.light_kind`` gives scene ``index`` of ``split`` (``scene_function`` of hyperspectral)."""
    from doefab.reconstruction.data import resample_bands, spectral_sample
    from doefab.reconstruction.spectra import light_kind

    cube = spectral_sample(rng, big, split, light_kind(split, index))
    return np.ascontiguousarray(resample_bands(cube, pair.wavelengths)), None, None, None


def depth_scene(split: str, index: int, rng, big: int, pair):
    """(scene [3, big, big], depth [big, big] in metres between ``pair``'s nearest and farthest planes, each
    plane's mask, where the depth was measured or None) (``scene_function`` of depth); for split ``real``
    measured depth, rendered at a neighbour's where it was not measured and not scored there."""
    from doefab.imaging.captures import plane_masks
    from doefab.reconstruction.data import depth_sample
    from doefab.reconstruction.realdata import depth_real_sample

    finite = [z for z in pair.depths if np.isfinite(z)]
    known = None
    if split == "real":
        scene, target, known = depth_real_sample(rng, big, near=min(finite), far=max(finite))
    else:
        scene, target = depth_sample(rng, big, split, near=min(finite), far=max(finite))
    return scene, target, plane_masks(torch.from_numpy(target), pair.depths), known
