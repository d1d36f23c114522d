"""Judge a fabricated part on its PSF: the design's task metric and the L1 distance to the nominal PSF.

``PSFJudge`` is built once per design (per worker): it holds the PSF plan on the refined grid, the nominal
(zero-error, same supersampling) coded PSF and the uncoded PSF (for crosstalk). Mounting errors move every
mask together (a decenter across the split line is x, along it y; a rotation turns the whole DOE about the
optical axis); an axial gap puts the DOE in front of the aperture plane (``doefab.optics.gap``: its diffraction
over the gap blurs the coded pattern and leaks coded light into the plain half); dual-pixel crosstalk mixes the uncoded PSF into the coded view (Eq. 29) unless calibrated
(the exact inverse restores the coded PSF).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.fabricate import fabricated_height, refined_camera

__all__ = ["PSFJudge", "alignment_chain"]


def alignment_chain(design_dir: Path) -> dict:
    """``{plate: plate it aligns to}`` from the mask set's manifest beside ``design_dir`` (chrome = 0)."""
    man = Path(design_dir).parent / "manifest.json"
    if man.is_file():
        try:
            return {int(k): int(v) for k, v in json.loads(man.read_text())["alignment_chain"].items()}
        except (KeyError, ValueError, TypeError):
            pass
    return {1: 0, 2: 0, 3: 0, 4: 0}


def compose_overlay(err: PartErrors, chain: dict) -> tuple[list, list]:
    """Absolute shift/rotation of each mask: its own error relative to the plate it aligns to, accumulated
    along the alignment chain, plus the mounting error that moves the whole DOE."""
    shifts, rots = [], []
    for m in range(4):
        plate, dx, dy, th = m + 1, 0.0, 0.0, 0.0
        seen = set()
        while plate != 0 and plate not in seen:
            seen.add(plate)
            k = plate - 1
            dx, dy, th = dx + err.overlay[k][0], dy + err.overlay[k][1], th + err.rotation[k]
            plate = chain.get(plate, 0)
        shifts.append((dx + err.mount_shift[0], dy + err.mount_shift[1]))
        rots.append(th + err.mount_rotation)
    return shifts, rots


class PSFJudge:
    """PSF-level judge of one design folder (``design.json`` + ``levels.npy``)."""

    def __init__(self, design_dir: str | Path, supersample: int = 2, threads: int | None = None):
        from doefab.design.design import Design
        from doefab.optics.psf import PSFPlan
        from doefab.tasks import get_task

        if threads:
            torch.set_num_threads(threads)
        self.design_dir = Path(design_dir)
        d = Design.load(self.design_dir)
        self.design, self.supersample = d, supersample
        self.task = get_task(d.task, **d.task_params)
        self.task.bind(d.camera)
        self.fine = refined_camera(d.camera, supersample)
        self.plan = PSFPlan(self.fine, d.wavelengths, d.depths, self.task.kernel_size, halves=("coded",))
        self.chain = alignment_chain(self.design_dir)
        t = time.perf_counter()
        self.nominal = self._coded(PartErrors())
        self.seconds_per_psf = time.perf_counter() - t
        self._uncoded = None

    def height(self, err: PartErrors) -> np.ndarray:
        shifts, rots = compose_overlay(err, self.chain)
        return fabricated_height(self.design.levels, self.design.camera, self.design.camera.design_wavelength,
                                 depth_scale=err.depth_scale, overlay=shifts, rotation=rots, edge_bias=err.edge_bias,
                                 roughness=err.roughness, supersample=self.supersample, seed=err.seed,
                                 corner_rounding=err.corner_rounding, roughness_corr=err.roughness_corr)

    def _coded(self, err: PartErrors) -> torch.Tensor:
        with torch.no_grad():
            return self.plan(self.height(err), gap=err.axial_gap).coded.double()

    def uncoded(self) -> torch.Tensor:
        if self._uncoded is None:
            from doefab.optics.psf import PSFPlan

            plan = PSFPlan(self.fine, self.design.wavelengths, self.design.depths, self.task.kernel_size,
                           halves=("uncoded",))
            with torch.no_grad():
                self._uncoded = plan(None).uncoded.double()
        return self._uncoded

    def psf_from_height(self, height) -> torch.Tensor:
        with torch.no_grad():
            return self.plan(height).coded.double()

    def score(self, coded: torch.Tensor, err: PartErrors | None = None) -> dict:
        """Task metric (mean, worst) and L1 distance to the nominal PSF (summed over pixels, mean over entries)."""
        if err is not None and any(err.crosstalk) and not err.calibrated:
            a, b = err.crosstalk
            coded = (1 - b) * coded + a * self.uncoded()  # the right (coded) view of Eq. 29
        m = self.task.metric(coded.float(), self.fine)
        l1 = float((coded - self.nominal).abs().sum(dim=(-1, -2)).mean())
        return {"metric": m["value"], "worst": m["worst"], "l1_to_nominal": l1}

    def evaluate(self, err: PartErrors) -> dict:
        if any(not 0 <= v < 0.5 for v in err.crosstalk):
            raise DoefabError("crosstalk ratios must be in [0, 0.5)")
        return self.score(self._coded(err), err)


RECON_TASK = {"streak": "hdr", "grating": "hyperspectral", "half-ring": "depth"}


class NetworkJudge:
    """Judge a part through the shipped reconstruction network of its design's task.

    Captures of a fixed subset of the test split are simulated with the fabricated coded PSF (the uncoded
    half has no DOE), then reconstructed by the shipped proposed network given (a) the nominal PSF it was
    trained with and (b) the fabricated PSF, as a user gets after measuring the part's PSF. Scored with the
    task's metrics (mean over the subset).
    """

    def __init__(self, psf_judge: PSFJudge, images: int = 4, size: int = 128, weights_dir=None):
        from doefab.optics.psf import PSFPlan
        from doefab.reconstruction.loader import load_reconstructor
        from doefab.reconstruction.specs import get_spec

        self.base = psf_judge
        d = psf_judge.design
        if d.task not in RECON_TASK:
            raise DoefabError(f"no reconstruction network for design task {d.task!r}")
        self.task = RECON_TASK[d.task]
        self.rec = load_reconstructor(self.task, "proposed", weights_dir)
        if self.rec.design_sha256 != _levels_sha(d.levels):
            raise DoefabError("the shipped network was trained for another design than this one: network-level "
                              "judgement needs weights trained for it (doefab train)")
        self.images, self.size = images, size
        self.plan = PSFPlan(psf_judge.fine, d.wavelengths, d.depths, get_spec(self.task).kernel,
                            halves=("coded", "uncoded"))

    def evaluate(self, err: PartErrors, height=None) -> dict:
        """Network metrics for part ``err`` (or for an explicit fine-grid ``height`` map)."""
        import dataclasses

        from doefab.reconstruction.metrics import metrics_for
        from doefab.reconstruction.specs import make_batch
        from doefab.reconstruction.train import _response

        nominal = self.rec.pair
        from doefab.optics.psf import as_height_tensor

        h = as_height_tensor(self.base.height(err) if height is None else height, self.plan.camera)
        uncoded = nominal.uncoded
        with torch.no_grad():
            if err.axial_gap > 0:  # the DOE's diffraction over the gap reaches the plain half too
                both = self.plan.gap_psfs(h, err.axial_gap)
                coded, uncoded = both["coded"].float(), both["uncoded"].float()
            else:
                coded = self.plan.half_psf("coded", h).float()
        if any(err.crosstalk) and not err.calibrated:
            a, b = err.crosstalk
            coded = (1 - b) * coded + a * uncoded
        pair = dataclasses.replace(nominal, coded=coded, uncoded=uncoded)
        batch = make_batch(self.task, "test", range(self.images), self.size, pair, _response(self.task, pair))
        out = {}
        for label, psf in (("nominal_psf", None), ("measured_psf", pair)):
            rows = [metrics_for(self.task, np.asarray(self.rec(c, u, psf=psf)), t.numpy())
                    for c, u, t in zip(*batch)]
            out[label] = {k: float(np.nanmean([r[k] for r in rows])) for k in rows[0]}
        return out


def _levels_sha(levels) -> str:
    from doefab.fabrication.levels import levels_sha256

    return levels_sha256(levels)
