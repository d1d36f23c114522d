"""Judge a part by what the camera delivers: captures through the part, reconstructed by the task's network.

For each part the judge computes both halves of the part's PSF (``PSFJudge``: relief as made, mount, stop),
renders a fixed set of validation scenes through them, and records them as the part's camera does
(``DualPixelCrosstalk``: Eq. 29's mix with per-column ratios at the crop's place on the sensor, shot and read
noise of the sensor the network was trained for (its weights record), then the unmix with the ratios its
simulated white-wall calibration estimated). The proposed network
reconstructs each capture twice — told the nominal PSF it was trained with, and told the part's own PSF pair
(as a user gets after measuring the part) — and the task's delivered metrics are averaged over the scenes.
Validation scenes, not test ones: the test split belongs to the final tables.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors, crosstalk_ratios

__all__ = ["NetworkJudge", "RECON_TASK", "crop_columns"]

RECON_TASK = {"streak": "hdr", "grating": "hyperspectral", "half-ring": "depth"}


def crop_columns(index: int, images: int, size: int, width_px: int) -> np.ndarray:
    """Sensor columns (pixels from the centre column) of scene ``index``'s crop: the scenes are spread across
    80 % of the calibrated width, so the crosstalk they see ranges over its profile."""
    centre = 0.0 if images < 2 else (index / (images - 1) - 0.5) * 0.8 * width_px
    return centre + np.arange(size) - (size - 1) / 2


class NetworkJudge:
    """Network-level judge of a design through the shipped proposed network of its task (or ``weights_dir``'s)."""

    def __init__(self, psf_judge, images: int = 4, size: int = 128, weights_dir=None):
        from doefab.fabrication.levels import levels_sha256
        from doefab.reconstruction.loader import load_reconstructor

        self.base = psf_judge
        d = psf_judge.design
        if d.task not in RECON_TASK:
            raise DoefabError(f"no reconstruction network for design task {d.task!r}")
        self.task = RECON_TASK[d.task]
        self.rec = load_reconstructor(self.task, "proposed", weights_dir, design=psf_judge.design_dir)
        if self.rec.design_sha256 != levels_sha256(d.levels):
            raise DoefabError("the network was trained for another design than this one: network-level judgement "
                              "needs weights trained for it (doefab train --design ...)")
        self.images, self.size = images, size
        self._nominal = None

    def pair(self, err: PartErrors, height=None):
        """The part's PSF pair (both halves) at the network's kernel (or that of an explicit ``height`` map)."""
        import dataclasses

        halves, k = ("coded", "uncoded"), self.rec.pair.coded.shape[-1]
        with torch.no_grad():
            got = (self.base.psfs(err, halves=halves, kernel=k) if height is None
                   else self.base.height_psfs(height, halves, k))
        return dataclasses.replace(self.rec.pair, coded=got["coded"].float(), uncoded=got["uncoded"].float())

    def crosstalk(self, err: PartErrors):
        """``index → DualPixelCrosstalk`` of the part's camera for each scene's crop."""
        from doefab.imaging.crosstalk import DualPixelCrosstalk

        noise = self.noise()

        def at(i: int):
            if not any(err.crosstalk):
                return None
            a, b, a_hat, b_hat = crosstalk_ratios(err, crop_columns(i, self.images, self.size,
                                                                    err.calibrated_width_px), noise)
            return DualPixelCrosstalk(a, b, (a_hat, b_hat) if err.calibrated else None)
        return at

    def sensor(self):
        """(response [3, C] or None, noise model) of the sensor the network was trained for: its record's noise
        and, hyperspectral, the response its architecture record holds (the default camera's when none)."""
        from doefab.reconstruction.models import arch_response

        spectral = self.task == "hyperspectral"
        response = arch_response(self.rec.meta["arch"], self.rec.pair.wavelengths) if spectral else None
        return response, self.noise()

    def noise(self):
        """The noise model of the sensor the network was trained for (its weights record's)."""
        from doefab.imaging.sensor import sensor_from_record

        return sensor_from_record(self.rec.meta.get("sensor")).noise()

    def evaluate(self, err: PartErrors, height=None) -> dict:
        """{"nominal_psf": metrics, "measured_psf": metrics} of the part (means over the scenes); ``height``: an
        explicit height map instead of the part's relief (the quantization study)."""
        from doefab.reconstruction.metrics import mean_metrics, metrics_for
        from doefab.reconstruction.specs import make_batch

        nominal = height is None and err == PartErrors()
        if nominal and self._nominal is not None:  # the error-free part: judged once (the tornado's base)
            return copy.deepcopy(self._nominal)
        pair = self.pair(err, height)
        response, noise = self.sensor()
        coded, uncoded, target = make_batch(self.task, "val", range(self.images), self.size, pair, response, noise,
                                            crosstalk=self.crosstalk(err))
        out = {}
        for label, psf in (("nominal_psf", None), ("measured_psf", pair)):
            rows = [metrics_for(self.task, np.asarray(self.rec(c, u, psf=psf)), t.numpy())
                    for c, u, t in zip(coded, uncoded, target)]
            out[label] = mean_metrics(rows)
        if nominal:
            self._nominal = copy.deepcopy(out)
        return out
