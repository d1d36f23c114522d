"""Captures the networks did not make: what a real camera adds that the reconstruction does not model exactly.

``Conditions`` says how a batch's captures are rendered:

- ``parts``: PSF pairs of as-fabricated parts drawn from the tolerance budget (relief as its masks made it,
  mount errors; ``doefab.tolerance``), one per scene in turn — while the network is told the nominal PSF (or
  the part's, when a user measured it);
- ``crosstalk``: a real sensor's dual-pixel crosstalk (``imaging.sensorcrosstalk.SensorCrosstalk``: dependent
  on the light's angle along both axes of the field and on the half it came through, varying from row to row, drifted
  since the calibration) mixed per Eq. 29 at each scene's place on the sensor, then unmixed with per-column ratios
  a simulated noisy white-wall calibration estimated (the user's pipeline): the part of the crosstalk a
  per-column calibration cannot hold stays in the captures (``describe()["crosstalk_residual_rms"]``);
- ``depth_planes``: depth scenes rendered through PSFs at planes ``depth_refine`` times finer (in inverse
  depth) than the network's cost volume scans, so depths fall between them;
- the sensor's noise (always).

``honest(task, design, split)`` draws them for a split (its own parts: training, validation and test never
share one; cached on disk, as the PSFs of dozens of fine planes cost minutes); ``clean()`` is the old,
inverse-crime setting: the nominal PSF at the network's planes, no crosstalk; ``measured(pair, split)``: one given
part (a measured ``psf_pair.npz``) with the budget's crosstalk (``evaluate --psf``, ``finetune --psf``). ``doefab
train`` and ``doefab evaluate`` hand them to ``reconstruction.train`` / ``reconstruction.evaluate``, which render
through whatever they are given (``specs.make_batch``).
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from doefab.applications import has
from doefab.reconstruction.data import PART_MODEL, PART_SEEDS  # every split's seeds in one place

__all__ = ["Conditions", "honest", "measured", "clean", "PART_SEEDS", "DEPTH_REFINE", "fine_planes", "for_splits",
           "CONDITIONS", "model_sources_sha256", "budget_sha256", "crop_columns", "crop_rows", "crosstalk_residual",
           "measured_crop"]

CONDITIONS = ("honest", "clean")

DEPTH_REFINE = 4


@dataclass
class Conditions:
    name: str = "clean"
    parts: list = field(default_factory=list)  # PSFPairs (both halves); empty: the nominal pair
    crosstalk: object = None  # PartErrors carrying the budget's sensor, or None
    split: str = "test"
    budget_sha256: str | None = None  # the budget the parts and crosstalk were drawn from (None: clean)
    camera: object = None  # a measured camera's DualPixelCrosstalk (crosstalk.json): used instead of ``crosstalk``

    def pair_for(self, index: int, nominal):
        return self.parts[index % len(self.parts)] if self.parts else nominal

    def crosstalk_for(self, index: int, images: int, size: int, noise="default"):
        """The DualPixelCrosstalk of scene ``index``: the true crosstalk of a sensor of its own (``SensorCrosstalk``,
        over its crop's rows and columns, the crops spread across the calibrated region by :func:`crop_rows`), in a
        capture session of its own, unmixed with the per-column estimate of a calibration with the sensor's
        ``noise`` (the captures' own); or None. With a measured ``camera``: :func:`measured_crop` of it."""
        if self.camera is not None:
            seed = np.random.SeedSequence([PART_SEEDS[self.split], index])
            return measured_crop(self.camera, index, images, size, np.random.default_rng(seed))
        if self.crosstalk is None:
            return None
        from dataclasses import replace

        from doefab.imaging.crosstalk import DualPixelCrosstalk
        from doefab.tolerance.errors import crosstalk_ratios

        err = replace(self.crosstalk, seed=int(np.random.SeedSequence([PART_SEEDS[self.split], index])
                                               .generate_state(1)[0]))
        place = (index % max(images, 1), images, size, err.calibrated_width_px)
        a, b, a_hat, b_hat = crosstalk_ratios(err, crop_columns(*place), noise, rows=crop_rows(*place))
        return DualPixelCrosstalk(a, b, (a_hat, b_hat) if err.calibrated else None)

    def describe(self) -> dict:
        """What the conditions are; ``crosstalk_residual_rms``: the (l→r, r→l) RMS of true − calibrated crosstalk
        ratio over the calibrated region that a noise-free calibration leaves (``SensorCrosstalk.residual``;
        None without crosstalk or calibration)."""
        xt = self.crosstalk
        out = {"name": self.name, "parts": len(self.parts), "crosstalk": xt is not None,
               "crosstalk_residual_rms": crosstalk_residual(xt) if xt is not None and xt.calibrated else None,
               "depth_planes": len(self.parts[0].depths) if self.parts else None, "budget_sha256": self.budget_sha256}
        if self.camera is not None:  # a measured camera (crosstalk.json): its ratios' digest instead of a budget's
            ratios = np.concatenate([np.ravel(self.camera.alpha_lr), np.ravel(self.camera.alpha_rl)])
            out.update(crosstalk=True, crosstalk_source="measured",
                       crosstalk_sha256=hashlib.sha256(ratios.astype(np.float64).tobytes()).hexdigest()[:16])
        return out


def crop_columns(index: int, images: int, size: int, width_px: int) -> np.ndarray:
    """Sensor columns (pixels from the centre column) of scene ``index``'s crop: the scenes are spread across
    80 % of the calibrated width, so the crosstalk they see ranges over its profile."""
    centre = 0.0 if images < 2 else (index / (images - 1) - 0.5) * 0.8 * width_px
    return centre + np.arange(size) - (size - 1) / 2


def measured_crop(camera, index: int, images: int, size: int, rng: np.random.Generator):
    """The ``DualPixelCrosstalk`` scene ``index`` sees through a measured camera (``crosstalk.json``: per-column
    ratios and their standard errors over the sensor's W columns): its crop's columns (``crop_columns``, spread
    across the sensor), unmixed with the file's ratios there; the true ratios the file's plus one draw of their
    standard errors (what its calibration could not pin down), within [0, 0.5)."""
    from doefab.errors import DoefabError
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    est = [np.asarray(camera.alpha_lr, np.float64), np.asarray(camera.alpha_rl, np.float64)]
    width = est[0].size
    if est[0].ndim != 1 or width < size:
        raise DoefabError(f"the measured crosstalk holds {width} columns: a {size}-px scene needs at least {size}; "
                          f"calibrate over the sensor's width or evaluate at a smaller --size")
    cols = np.clip(np.round(crop_columns(index, images, size, width) + (width - 1) / 2).astype(int), 0, width - 1)
    se = camera.standard_error or (np.zeros(width), np.zeros(width))
    true = [np.clip(e[cols] + np.asarray(s, np.float64)[cols] * rng.standard_normal(size), 0.0, 0.499)
            for e, s in zip(est, se)]
    return DualPixelCrosstalk(true[0], true[1], (est[0][cols], est[1][cols]))


def crop_rows(index: int, images: int, size: int, width_px: int) -> np.ndarray:
    """Sensor rows (pixels from the centre row) of scene ``index``'s crop: ``crop_columns`` in reverse
    order, so the crops lie along the calibrated region's diagonal and see its crosstalk along both axes."""
    return crop_columns(max(images - 1 - index, 0), images, size, width_px)


def crosstalk_residual(err) -> list:
    """(l→r, r→l) RMS of true − calibrated crosstalk ratio over the calibrated region and 8 capture sessions of the
    sensor of ``err`` (a ``PartErrors``), its calibration of ``err.calibration_rows`` rows without noise: what the
    per-column calibration cannot remove (rounded to 3 significant digits)."""
    from doefab.tolerance.errors import sensor_crosstalk

    return [float(f"{x:.3g}") for x in sensor_crosstalk(err).residual(err.calibration_rows)]


def clean() -> Conditions:
    return Conditions()


def fine_planes(depths, refine: int = DEPTH_REFINE) -> tuple:
    """Planes ``refine`` times finer than ``depths`` everywhere, nearest first: each of ``depths`` (metres > 0,
    ``inf`` allowed) and ``refine − 1`` planes between each two neighbours, evenly spaced in inverse depth (as the
    blur grows). A scene's depth is thus rendered at most a ``2·refine``-th of the network's plane spacing from its
    own, wherever it lies, and the network's planes are among them (their PSFs are the rendering planes' own).

    Example: ``fine_planes([1.0, 2.0], 2)`` → ``(1.0, 1.3333…, 2.0)`` (1/z = 1, 0.75, 0.5 per metre)."""
    from doefab.errors import DoefabError

    zs = sorted({float(z) for z in depths})
    if int(refine) != refine or refine < 1 or not zs or not zs[0] > 0:
        raise DoefabError(f"fine planes need depths > 0 m and a whole refinement ≥ 1, got {list(depths)} and "
                          f"{refine}: e.g. fine_planes([1.0, 2.0], 4)")
    out = zs[:1]
    for near, far in zip(zs, zs[1:]):
        inv = np.linspace(1 / near, 1 / far, refine + 1)[1:-1]
        out += [float(1 / v) for v in inv] + [far]
    return tuple(out)


def honest(task: str, design_dir, split: str, parts: int = 6, budget: dict | None = None,
           progress: bool = False) -> Conditions:
    """A split's honest conditions: ``parts`` fabricated parts from ``budget`` (default: the shipped one), the
    budget's crosstalk with calibration, and for depth PSFs at ``DEPTH_REFINE``× finer planes."""
    from doefab.tolerance.errors import load_budget

    budget = budget or load_budget()
    pairs = _parts(task, Path(design_dir), split, parts, budget, progress)
    return Conditions(name="honest", parts=pairs, split=split, **_budget_crosstalk(budget))


def measured(pair, split: str, budget: dict | None = None, crosstalk: bool = True, camera=None) -> Conditions:
    """Captures through one given part: every scene of ``split`` rendered through ``pair`` (a ``PSFPair`` with both
    halves: a measured part's ``psf_pair.npz``, or a model fitted to it), with the budget's crosstalk unmixed by
    a noisy calibration as in :func:`honest` (``crosstalk``; default budget: the shipped one), or the measured
    camera's (``camera``: ``DualPixelCrosstalk.load("crosstalk.json")``; :func:`measured_crop`). Depth scenes
    fall on ``pair``'s planes."""
    from doefab.tolerance.errors import load_budget

    if camera is not None and crosstalk:
        return Conditions(name="measured", parts=[pair], split=split, camera=camera)
    xt = _budget_crosstalk(budget or load_budget())
    return Conditions(name="measured", parts=[pair], split=split, **(xt if crosstalk else {}))


def _budget_crosstalk(budget: dict) -> dict:
    """``Conditions`` fields of ``budget``'s sensor: its crosstalk (None when it has none) and the budget's digest."""
    from dataclasses import replace

    from doefab.tolerance.errors import sensor_errors
    from doefab.tolerance.surrogate import base_part

    sensor = replace(base_part(budget), **sensor_errors(budget))
    return {"crosstalk": sensor if any(sensor.crosstalk) else None, "budget_sha256": budget_sha256(budget)}


def budget_sha256(budget: dict | None = None) -> str:
    """The 16-hex-digit digest of a tolerance budget (default: the shipped one) that honest captures record as
    ``Conditions.budget_sha256``: evaluations made under another budget are told apart by it.

    Example: ``budget_sha256() == honest("hdr", "masks/streak/design", "val").budget_sha256``."""
    from doefab.tolerance.errors import budget_values, load_budget

    b = budget_values(budget or load_budget())
    return hashlib.sha256(json.dumps(b, sort_keys=True, default=str).encode()).hexdigest()[:16]


def model_sources_sha256(packages=PART_MODEL) -> str:
    """SHA-256 of the source of the subpackages that compute a fabricated part's PSFs: part of the cache key, so
    parts cached by another version of that code (a model fix, an upgrade) are computed afresh, never reused."""
    from doefab.io import sources_sha256

    return sources_sha256(Path(__file__).resolve().parent.parent, tuple(packages))


def metric_sha256(design) -> str:
    """SHA-256 (16 hex digits) of the 0/1 masks of the pixels a design's task metric counts (``Task.band_masks`` on
    its camera): part of a tolerance run's identity, so parts scored on another metric are not mixed in.

    Example: ``metric_sha256(Design.load("masks/streak/design"))`` changes where the streak's arms do."""
    from doefab.tasks import get_task

    task = get_task(design.task, **design.task_params)
    task.bind(design.camera)
    masks = np.ascontiguousarray(task.band_masks(design.camera).detach().cpu().numpy(), np.float64)
    return hashlib.sha256(masks.tobytes()).hexdigest()[:16]


def _key(task, design, split, n, budget, kernel, chain) -> str:
    from doefab.fabrication.levels import levels_sha256
    from doefab.tolerance.errors import budget_values

    b = budget_values(budget)
    planes = list(fine_planes(design.depths)) if has(task, "depth") else None  # the rendering planes themselves
    text = json.dumps([task, levels_sha256(design.levels), design.n_levels, split, n, b, planes,
                       PART_SEEDS[split], list(design.depths), list(design.wavelengths), kernel,
                       design.camera.to_dict(), sorted(chain.items()), model_sources_sha256()], sort_keys=True,
                      default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _parts(task, design_dir: Path, split: str, n: int, budget: dict, progress: bool) -> list:
    """PSF pairs of ``n`` parts sampled from the budget (seeded by the split), at the network's kernel; cached."""
    from dataclasses import replace

    from doefab._memory import keep_freed_memory
    from doefab.design.design import Design
    from doefab.fabrication.process import mask_count
    from doefab.io import atomic_write_bytes, cache_root
    from doefab.optics.psf import PSFPair
    from doefab.reconstruction.specs import network_kernel
    from doefab.tolerance.errors import sample_errors
    from doefab.tolerance.judge import PSFJudge, alignment_chain

    design = Design.load(design_dir)
    depths = fine_planes(design.depths) if has(task, "depth") else design.depths
    kernel = network_kernel(task, design.task_params.get("kernel_size"))
    chain = alignment_chain(design_dir, mask_count(design.n_levels))
    # fabricated parts' PSFs take minutes: kept between runs in the cache (``doefab.io.cache_root``)
    path = cache_root() / "conditions" / f"{task}-{_key(task, design, split, n, budget, kernel, chain)}.pt"
    if path.is_file():
        try:
            data = torch.load(path, weights_only=True)
            return [PSFPair(c, u, tuple(design.wavelengths), depths, design.camera.sensor_pitch)
                    for c, u in zip(data["coded"], data["uncoded"])]
        except Exception:  # noqa: BLE001 - a damaged cache is recomputed
            path.unlink(missing_ok=True)
    keep_freed_memory()  # each part's transforms reuse the blocks the last one freed (about half its time)
    judge = PSFJudge(replace(design, depths=depths), 1, chain=chain)
    children = np.random.SeedSequence(PART_SEEDS[split]).spawn(n)
    coded, uncoded = [], []
    it = range(n)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"fabricated parts ({split})", unit="part")
    for i in it:
        err = sample_errors(budget, np.random.default_rng(children[i]), seed=int(children[i].generate_state(1)[0]),
                            n_masks=judge.n_masks)
        err = replace(err, crosstalk=(0.0, 0.0))  # crosstalk acts on the captures, not on the PSF
        with torch.no_grad():
            got = judge.psfs(err, halves=("coded", "uncoded"), kernel=kernel)
        coded.append(got["coded"].float())
        uncoded.append(got["uncoded"].float())
    buf = io.BytesIO()
    torch.save({"coded": coded, "uncoded": uncoded}, buf)
    atomic_write_bytes(path, buf.getvalue())  # atomic_write_bytes makes the cache folder
    return [PSFPair(c, u, tuple(design.wavelengths), depths, design.camera.sensor_pitch) for c, u in zip(coded, uncoded)]


def for_splits(task: str, design, kind: str, splits=("train", "val"), parts: int = 6, progress: bool = False,
               budget: dict | None = None) -> dict:
    """{split: Conditions} of a kind ("honest" or "clean") for a task's design (None: the committed one), its
    parts drawn from ``budget`` (default: the shipped one)."""
    from doefab.errors import DoefabError
    from doefab.reconstruction.specs import design_dir

    if kind not in CONDITIONS:
        raise DoefabError(f"conditions must be one of {CONDITIONS}, got {kind!r}")
    if kind == "clean":
        return {s: clean() for s in splits}
    return {s: honest(task, design or design_dir(task), s, parts, budget, progress=progress) for s in splits}
