"""Judge a part by what the camera delivers: captures through the part, reconstructed by the task's network.

For each part the judge computes both halves of the part's PSF (``PSFJudge``: relief as made, mount, stop) and
renders scenes through them on the path ``doefab evaluate`` takes (``specs.make_batch`` under a
``tolerance.conditions.Conditions`` of that one part): depth scenes through the part's PSFs at planes
``DEPTH_REFINE`` times finer than the network's (depths fall between its planes), the views mixed by the
sensor's crosstalk at each crop's place and unmixed with a calibration drawn with the captures' noise, the
sensor's shot and read noise (the sensor the network was trained for: in a scene's run, the scene's). The
proposed network reconstructs each capture twice — told the nominal PSF it was trained with, and told the
part's own PSF pair at its planes (as a user gets after measuring the part) — on one torch thread, and each
scene's delivered metrics are kept (``scenes``) as well as their means (``evaluate``). The error-free part
judged on the scenes an evaluation reads scores what that evaluation scores through the error-free part.

The scenes are the test split's, as the reconstruction tables' (the study states what parts deliver; nothing is
chosen on it), ``SIZE`` px square as ``doefab evaluate``'s, ``SCENES`` per part by default: a cost, not a
guarantee. ``delivered.variance_components`` measures, on each study's own parts, whether a part's scene noise lies
below the part-to-part spread and the report says so; on the committed designs (docs/results/tolerance.md) 8 scenes
put it there for the half-ring's depth, tie it for the streak's highlights and leave the grating's parts, whose
spread no F test resolves, unresolved.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from doefab.applications import View, has, of_design
from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors

__all__ = ["NetworkJudge", "RECON_TASK", "judge_settings", "SCENES", "SIZE", "SPLIT", "LABELS"]

RECON_TASK = View(lambda a: a.name, key=lambda a: a.design_task)  # a view of ``doefab.applications``
SCENES = 8  # scenes per part (the report measures the scene noise against the spread: module docstring)
SIZE = 256  # scene side (px), as ``doefab evaluate``'s
SPLIT = "test"  # the reconstruction tables' scenes
SPLITS = ("val", "test")
LABELS = ("nominal_psf", "measured_psf")  # what the network is told: the nominal PSF, the part's measured pair


def judge_settings(networks) -> dict:
    """The judge's scenes a study's ``networks`` argument asks for: ``True`` the defaults, a dict some of
    {"images": scenes per part ≥ 1, "size": px, a multiple of 32 ≥ 64, "split": "val" or "test"} (the rest
    default). A DoefabError names a bad entry, its value and one that works."""
    given = networks if isinstance(networks, dict) else {}
    unknown = sorted(set(given) - {"images", "size", "split"})
    if unknown:
        raise DoefabError(f"network judge settings {unknown} are not known: give images, size or split")
    s = {"images": SCENES, "size": SIZE, "split": SPLIT, **given}
    images, size = s["images"], s["size"]
    if isinstance(images, bool) or not isinstance(images, int) or images < 1:
        raise DoefabError(f"network judge images = {images!r} must be a whole number of scenes ≥ 1, e.g. {SCENES}")
    if isinstance(size, bool) or not isinstance(size, int) or size < 64 or size % 32:
        raise DoefabError(f"network judge size = {size!r} px must be a multiple of 32 and at least 64, e.g. {SIZE}")
    if s["split"] not in SPLITS:
        raise DoefabError(f"network judge split = {s['split']!r} must be one of {', '.join(SPLITS)}, e.g. {SPLIT}")
    return s


class NetworkJudge:
    """Network-level judge of a design through the proposed network of its task (the shipped one, or
    ``weights_dir``'s): ``images`` scenes of ``size``² px from ``split``, rendered as ``doefab evaluate`` renders
    them (``judge_settings`` checks the three)."""

    def __init__(self, psf_judge, images: int = SCENES, size: int = SIZE, weights_dir=None, split: str = SPLIT):
        from doefab.fabrication.levels import levels_sha256
        from doefab.reconstruction.loader import load_reconstructor

        s = judge_settings({"images": images, "size": size, "split": split})
        self.base = psf_judge
        d = psf_judge.design
        if of_design(d.task) is None:
            raise DoefabError(f"no reconstruction network for design task {d.task!r}")
        self.task = of_design(d.task).name
        self.rec = load_reconstructor(self.task, "proposed", weights_dir, design=psf_judge.design_dir,
                                      device=psf_judge.device)  # the network where the part's PSFs are
        if self.rec.design_sha256 != levels_sha256(d.levels):
            raise DoefabError("the network was trained for another design than this one: network-level judgement "
                              "needs weights trained for it (doefab train --design ...)")
        self.images, self.size, self.split = s["images"], s["size"], s["split"]
        self._fine = None
        self._nominal = None

    @property
    def renders_elsewhere(self) -> bool:
        """Whether the captures are rendered on other planes than the network's (depth: ``render_judge``)."""
        return has(self.task, "depth")

    @property
    def render_judge(self):
        """The ``PSFJudge`` whose PSFs make the captures: for depth one on ``conditions.fine_planes`` of the
        design's planes (the scenes' depths fall between the network's planes, as in ``doefab evaluate``), else
        the design's own."""
        if not self.renders_elsewhere:
            return self.base
        if self._fine is None:
            from dataclasses import replace

            from doefab.tolerance.conditions import fine_planes
            from doefab.tolerance.judge import PSFJudge

            b = self.base
            self._fine = PSFJudge(replace(b.design, depths=fine_planes(b.design.depths)), b.supersample,
                                  margin=b.margin, chain=b.chain, device=b.device)
        return self._fine

    def pair(self, err: PartErrors, height=None, judge=None):
        """The part's PSF pair (both halves) at the network's kernel (or that of an explicit ``height`` map), on
        ``judge``'s planes (default: the network's — the pair a user measures and tells the network)."""
        import dataclasses

        judge = judge or self.base
        halves, k = ("coded", "uncoded"), self.rec.pair.coded.shape[-1]
        with torch.no_grad():
            got = (judge.psfs(err, halves=halves, kernel=k) if height is None
                   else judge.height_psfs(height, halves, k))
        return dataclasses.replace(self.rec.pair, coded=got["coded"].float(), uncoded=got["uncoded"].float(),
                                   depths=tuple(judge.design.depths))

    def at_network_planes(self, rendered):
        """The pair ``rendered`` (on the rendering planes) at the network's planes when those are among them
        (``conditions.fine_planes`` keeps them: a PSF at a plane is the same whichever other planes are
        computed), else None."""
        import dataclasses

        from doefab.tolerance.judge import planes_among

        take = planes_among(self.rec.pair.depths, rendered.depths)
        if take is None:
            return None
        return dataclasses.replace(rendered, coded=rendered.coded[take], uncoded=rendered.uncoded[take],
                                   depths=tuple(self.rec.pair.depths))

    def rendered_pair(self, err: PartErrors, height=None):
        """(rendering pair, the pair the network is told): the part's PSFs on the rendering planes and at the
        network's. For depth the second is taken from the first, and the base judge keeps it for the part's PSF
        metric (``PSFJudge.take_planes``), which then computes none of them again (where a part's PSFs are shared at
        all: not across an axial gap in front of a lens stop, ``PSFJudge.psfs``)."""
        if self.render_judge is self.base:
            pair = self.pair(err, height)
            return pair, pair
        rendered = self.pair(err, height, self.render_judge)
        measured = self.at_network_planes(rendered)
        if measured is None:
            return rendered, self.pair(err, height)
        self.base.take_planes(self.render_judge, self.render_judge.source_of(err, height))
        return rendered, measured

    def conditions(self, err: PartErrors, rendered):
        """The ``Conditions`` of one part (``tolerance.conditions``): its captures made through ``rendered`` (its
        PSF pair on the rendering planes), its camera's crosstalk unmixed with a calibration drawn with the
        captures' noise, the scenes of the judge's split."""
        from doefab.tolerance.conditions import Conditions

        return Conditions(name="part", parts=[rendered], crosstalk=err if any(err.crosstalk) else None,
                          split=self.split)

    def sensor(self):
        """(response [3, C] or None, noise model) of the sensor the network was trained for: its record's noise
        and, hyperspectral, the response its architecture record holds (the default camera's when none). The
        pipeline judges through a network only when it was trained for the scene's sensor, so this is the
        scene's."""
        from doefab.imaging.sensor import sensor_from_record
        from doefab.reconstruction.spectralnet import arch_response

        spectral = has(self.task, "spectral")
        response = arch_response(self.rec.meta["arch"], self.rec.pair.wavelengths) if spectral else None
        return response, sensor_from_record(self.rec.meta.get("sensor")).noise()

    def scenes(self, err: PartErrors, height=None) -> dict:
        """{label: {metric: [value on each scene]}} of the part, the network told the nominal PSF
        ("nominal_psf") and the part's own pair ("measured_psf"); ``height``: an explicit height map instead of
        the part's relief (the quantization study). Each scene is made by ``specs.make_batch`` under the part's
        ``conditions`` and scored on one torch thread, exactly as ``doefab evaluate`` scores the proposed network
        on the same scenes."""
        from doefab.reconstruction.evaluate import one_thread
        from doefab.reconstruction.metrics import metrics_for
        from doefab.reconstruction.specs import make_batch

        nominal = height is None and err == PartErrors()
        if nominal and self._nominal is not None:  # the error-free part: judged once (the tornado's base)
            return copy.deepcopy(self._nominal)
        rendered, measured = self.rendered_pair(err, height)
        cond = self.conditions(err, rendered)
        response, noise = self.sensor()
        rows = {label: [] for label in LABELS}
        with one_thread():
            for i in range(self.images):
                coded, uncoded, target = make_batch(self.task, self.split, [i], self.size, self.rec.pair, response,
                                                    noise, conditions=cond, images=self.images)
                for label, psf in zip(LABELS, (None, measured)):
                    out = np.asarray(self.rec(coded[0], uncoded[0], psf=psf))
                    rows[label].append(metrics_for(self.task, out, target[0].numpy()))
        got = {label: {k: [float(r[k]) for r in rs] for k in rs[0]} for label, rs in rows.items()}
        if nominal:
            self._nominal = copy.deepcopy(got)
        return got

    @staticmethod
    def means(per_scene: dict) -> dict:
        """{label: {metric: mean over the scenes that define it}} of ``scenes``' result (``mean_metrics``)."""
        from doefab.reconstruction.metrics import mean_metrics

        return {label: mean_metrics([dict(zip(m, vals)) for vals in zip(*m.values())])
                for label, m in per_scene.items()}

    def evaluate(self, err: PartErrors, height=None) -> dict:
        """{"nominal_psf": metrics, "measured_psf": metrics} of the part: ``scenes``' means over the scenes."""
        return self.means(self.scenes(err, height))
