"""A part's plain half served from another part's (``MountedPlan.plain_key``): only where its transmittance is exactly
plain glass over that half, and then bit for bit what the part computes for itself."""

from types import SimpleNamespace

import pytest
import torch

from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

HALVES = ("coded", "uncoded")


def _counting(monkeypatch, judge):
    """The halves each ``MountedPlan.psfs`` call of ``judge`` computes, in order."""
    from doefab.tolerance.mounted import MountedPlan

    calls, real = [], MountedPlan.psfs

    def psfs(self, field, decenter=(0.0, 0.0), gap=0.0, halves=None):
        calls.append(tuple(halves or self.halves))
        return real(self, field, decenter, gap, halves)
    monkeypatch.setattr(MountedPlan, "psfs", psfs)
    return calls


def _the_second_computes_its_coded_half_alone(monkeypatch, design, ask, first, second):
    """``ask(judge, first, HALVES)``, then ``second``'s, which must compute its coded half alone and equal, bit for
    bit, what a fresh judge computes for it; returns (the second's, the first's) PSFs."""
    judge = PSFJudge(design)
    before = ask(judge, first, HALVES)
    calls = _counting(monkeypatch, judge)
    got = ask(judge, second, HALVES)
    assert calls == [("coded",)]
    monkeypatch.undo()
    own = ask(PSFJudge(design), second, HALVES)
    for h in HALVES:
        assert torch.equal(got[h], own[h]), h
    return got, before


@pytest.mark.parametrize("err", [PartErrors(depth_scale=(1.04, 1.0, 0.97, 1.0)), PartErrors(mount_tilt=0.02),
                                 PartErrors(axial_gap=1e-3, depth_scale=(1.02,) * 4)],
                         ids=["etch depth", "mount tilt", "a gap behind a DOE that is the stop"])
def test_a_relief_error_leaves_the_plain_half_to_the_error_free_parts_psf(depth_design, monkeypatch, err):
    """Errors that change only the relief on the coded side: after the error-free part, the part computes its coded
    half alone, and its plain half is, bit for bit, the one a fresh judge computes from the part's own relief."""
    got, nominal = _the_second_computes_its_coded_half_alone(monkeypatch, depth_design, PSFJudge.psfs, PartErrors(),
                                                             err)
    assert not torch.equal(got["coded"], nominal["coded"])  # the error is seen


@pytest.mark.parametrize("err", [PartErrors(mount_shift=(5.4e-6, 0.0)), PartErrors(mount_shift=(0.0, 5.4e-6)),
                                 PartErrors(overlay=((10.8e-6, 0.0),) * 4), PartErrors(edge_bias=0.3e-6)],
                         ids=["decenter across", "decenter along", "overlay across the split",
                              "edge bias at the split"])
def test_a_part_whose_plain_half_differs_computes_its_own(depth_design, monkeypatch, err):
    """A decenter moves the split and the lens against the die, and an overlay or an edge bias that carries the
    relief (which here reaches the split) across it puts it into the plain half: such a part computes both halves,
    and its plain half differs from the error-free part's."""
    judge = PSFJudge(depth_design)
    nominal = judge.psfs(PartErrors(), HALVES)
    calls = _counting(monkeypatch, judge)
    got = judge.psfs(err, HALVES)
    assert calls == [HALVES]
    assert not torch.equal(got["uncoded"], nominal["uncoded"])


def test_the_plain_key_reads_only_the_samples_the_plain_half_covers(depth_design):
    """The key is given exactly when the transmittance is 1 on every sample the plain half covers: a change on a
    sample it does not cover leaves it, one on a sample it covers (however small) takes it away, and the key
    tells decenters apart; a gap the lens's stop propagates gives none."""
    judge = PSFJudge(depth_design)
    plan = judge.plan(HALVES, 0.0)
    (r0, r1), (c0, c1) = plan.window
    g = plan.geo["uncoded"]
    cover = plan.coverage("uncoded", 0.0)
    rows, cols = torch.nonzero(cover == 0, as_tuple=True)
    outside = (g.rows.start - r0 + int(rows[0]), g.cols.start - c0 + int(cols[0]))
    rows, cols = torch.nonzero((cover > 0) & (cover < 1), as_tuple=True)  # a rim sample, partly covered
    assert float(cover[rows[-1], cols[-1]]) > 1e-3
    inside = (g.rows.start - r0 + int(rows[-1]), g.cols.start - c0 + int(cols[-1]))

    def field_with(at, value):
        t = torch.ones(r1 - r0, c1 - c0, dtype=torch.complex64)
        if at is not None:
            t[at] = value
        return lambda i: t

    key = plan.plain_key(field_with(None, 0))
    assert key is not None and key == plan.plain_key(field_with(outside, 0.3 + 0.2j))
    assert plan.plain_key(field_with(inside, complex(1.0, 1e-7))) is None
    assert len({key, plan.plain_key(field_with(None, 0), decenter=(0.0, 1e-6)),
                plan.plain_key(field_with(None, 0), decenter=(1e-6, 0.0))}) == 3
    # a gap moves nothing when the DOE is the stop (``MountedPlan.psfs`` then does not propagate it)
    assert plan.camera.doe_is_stop and plan.plain_key(field_with(None, 0), gap=1e-3) == key
    plan.camera = SimpleNamespace(doe_is_stop=False)  # the lens the stop: the gap carries the relief across
    assert plan.plain_key(field_with(None, 0), gap=1e-3) is None


def test_a_quantized_heights_plain_half_is_the_error_free_parts(depth_design, monkeypatch):
    """The quantization study's height maps leave the plain half plain glass: after one, another computes its coded
    half alone, and its plain half is the one a fresh judge computes for it, bit for bit."""
    import numpy as np

    h = np.asarray(PSFJudge(depth_design).design.height, np.float64)
    coarse = np.where(np.arange(h.shape[1])[None, :] < 50, np.round(h / h.max() * 3) / 3 * h.max(), h)
    got, first = _the_second_computes_its_coded_half_alone(monkeypatch, depth_design, PSFJudge.height_psfs, h, coarse)
    assert not torch.equal(got["coded"], first["coded"])


@pytest.mark.parametrize("err", [PartErrors(crosstalk=(0.03, 0.02), crosstalk_slope=0.01, calibrated=False),
                                 PartErrors(seed=7, roughness_corr=5e-6), PartErrors(axial_gap=2e-3)],
                         ids=["sensor crosstalk", "the seed and correlation of no roughness", "a gap behind the stop"])
def test_a_part_that_differs_only_beyond_its_pupil_computes_no_psf(depth_design, monkeypatch, err):
    """What acts at the sensor (crosstalk and its calibration), a roughness's parameters when there is none, and an
    axial gap behind a DOE that is the stop change no PSF: after the error-free part, such a part computes none."""
    judge = PSFJudge(depth_design)
    nominal = judge.psfs(PartErrors(), HALVES)
    calls = _counting(monkeypatch, judge)
    got = judge.psfs(err, HALVES)
    assert calls == [] and all(torch.equal(got[h], nominal[h]) for h in HALVES)


def test_a_rough_parts_seed_is_its_own(depth_design, monkeypatch):
    """With roughness, the seed and the correlation length draw the surface: each is a part of its own, computing
    both halves."""
    judge = PSFJudge(depth_design)
    a = judge.psfs(PartErrors(roughness=20e-9, seed=1), HALVES)
    calls = _counting(monkeypatch, judge)
    b = judge.psfs(PartErrors(roughness=20e-9, seed=2), HALVES)
    c = judge.psfs(PartErrors(roughness=20e-9, seed=2, roughness_corr=4e-6), HALVES)
    assert calls == [HALVES, HALVES]  # the roughness covers the plain half's samples too
    assert not torch.equal(a["coded"], b["coded"]) and not torch.equal(b["coded"], c["coded"])


def test_planes_taken_from_a_rendering_judge_carry_the_plain_half_it_shared(depth_design, monkeypatch):
    """A depth part's rendering judge keeps its plain half under the error-free part's key; the design's judge that
    takes the part's planes (``take_planes``) is served both halves without computing, bit for bit a fresh one's."""
    from dataclasses import replace

    from doefab.tolerance.conditions import fine_planes

    net = PSFJudge(depth_design)
    fine = PSFJudge(replace(net.design, depths=fine_planes(net.design.depths)), margin=net.margin, chain=net.chain)
    err = PartErrors(depth_scale=(1.04, 1.0, 0.97, 1.0))
    fine.psfs(PartErrors(), HALVES, 31)
    fine.psfs(err, HALVES, 31)
    assert (fine.source_of(err), "uncoded") not in fine._kept  # kept under the error-free part's plain key
    net.take_planes(fine, fine.source_of(err))
    fresh = PSFJudge(depth_design).psfs(err, HALVES, 31)

    def no_plan(*a, **k):
        raise AssertionError("computed a PSF the rendering planes hold")
    monkeypatch.setattr(net, "plan", no_plan)
    served = net.psfs(err, HALVES, 31)
    assert all(torch.equal(served[h], fresh[h]) for h in HALVES)
