"""Where depth scenes are rendered (``conditions.fine_planes``) and how a part's PSFs at the network's planes are
taken from its rendering planes' (``PSFJudge.take_planes``)."""

import numpy as np
import pytest
import torch

from doefab.tolerance import conditions as C


def _rendering_judge(net, depths):
    """A judge of ``net``'s grid, margin, chain and device on ``conditions.fine_planes(depths)`` (as the network
    judge's ``render_judge`` is made)."""
    from dataclasses import replace

    from doefab.tolerance.judge import PSFJudge

    return PSFJudge(replace(net.design, depths=C.fine_planes(depths)), net.supersample, margin=net.margin,
                    chain=net.chain, device=net.device)


def _computing_fails(monkeypatch, judge):
    """From here on ``judge`` computing a PSF fails the test."""
    def no_plan(*a, **k):
        raise AssertionError("computed a PSF the rendering planes hold")
    monkeypatch.setattr(judge, "plan", no_plan)


@pytest.mark.parametrize("net", [np.arange(1.0, 5.01, 0.25), 1 / np.linspace(1.0, 0.2, 17),
                                 np.array([0.5, 0.7, 3.0])])
def test_a_rendered_depth_is_never_farther_from_its_plane_than_a_fraction_of_the_networks_spacing(net):
    """Wherever a depth lies, the plane it is rendered at (the nearest in inverse depth, ``plane_masks``) is within
    half a rendering step, a ``2·refine``-th of the network's local plane spacing in inverse depth: checked by brute
    force on a dense grid of depths, for planes even in depth (the shipped depth design's), even in inverse depth
    and uneven."""
    fine = 1 / np.array(C.fine_planes(net))
    nets = np.sort(1 / net)
    q = np.linspace(nets[0], nets[-1], 200_001)  # inverse depths
    err = np.abs(q[:, None] - fine[None, :]).min(axis=1)
    j = np.clip(np.searchsorted(nets, q), 1, len(nets) - 1)
    spacing = nets[j] - nets[j - 1]  # the network's plane spacing where q lies
    assert np.all(err <= spacing / (2 * C.DEPTH_REFINE) * (1 + 1e-9))


def test_fine_planes_keep_a_plane_at_infinity_and_a_single_plane():
    assert C.fine_planes([2.0, 1.0], 2) == pytest.approx((1.0, 4 / 3, 2.0), rel=1e-15)
    assert C.fine_planes([2.0, float("inf")], 2) == (2.0, 4.0, float("inf"))
    assert C.fine_planes([3.0]) == (3.0,)


@pytest.mark.parametrize("device", [pytest.param(None, id="auto"), pytest.param("cuda", id="cuda", marks=[
    pytest.mark.cuda, pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")])])
def test_a_parts_psfs_at_the_networks_planes_are_those_of_its_rendering_planes(depth_design, device):
    """The network judge takes a part's pair at the network's planes from the PSFs of its rendering planes: a PSF at
    a plane does not depend on which other planes are computed with it (plane batches of different sizes), so the
    rendering planes' PSFs at the network's planes are, bit for bit on the CPU (to float32 rounding on a GPU, whose
    kernels may differ with the batch), those computed on the network's planes alone."""
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.judge import PSFJudge

    net = PSFJudge(depth_design, 1, device=device)
    fine = _rendering_judge(net, net.design.depths)
    err = PartErrors(mount_shift=(3e-6, -2e-6), mount_rotation=0.01)
    halves = ("coded", "uncoded")
    alone, rendered = net.psfs(err, halves, 31), fine.psfs(err, halves, 31)
    take = [fine.design.depths.index(z) for z in net.design.depths]
    assert len(take) == 3 and len(fine.design.depths) == 9
    for h in halves:
        if net.device.type == "cpu":
            assert torch.equal(rendered[h][take], alone[h])
        else:
            torch.testing.assert_close(rendered[h][take], alone[h], rtol=1e-4, atol=1e-6 * float(alone[h].max()))
        assert not torch.equal(rendered[h][take], rendered[h][[t + 1 if t + 1 < 9 else t - 1 for t in take]])


def test_the_psf_metric_of_a_depth_part_is_served_from_its_rendering_planes(depth_design, monkeypatch):
    """After the network judge took a part's pair from its rendering planes (``take_planes``), the design's judge
    serves that part's PSF metric from them, at its own kernel or the network's, without computing a PSF: the same,
    bit for bit, as a judge with nothing kept computes; another part (one the rendering judge also computed, later)
    is computed, and what was taken stays when the store is over its size."""
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.judge import PSFJudge

    net = PSFJudge(depth_design, 1)
    fine = _rendering_judge(net, net.design.depths)
    err, other = PartErrors(mount_shift=(3e-6, -2e-6), mount_rotation=0.01), PartErrors(mount_shift=(3e-6, 2e-6))
    net.psfs(err, ("coded",), 21)  # kept first, then another part: the part's coded half is the oldest entry,
    net.psfs(other, ("coded",), 21)  # taking it again makes it the newest, so the full store drops the other part
    net.KEEP_BYTES = 1
    fine.psfs(err, ("coded", "uncoded"), 31)
    fine.psfs(other, ("coded", "uncoded"), 31)
    net.take_planes(fine, fine.source_of(err))
    fresh = PSFJudge(depth_design, 1).psfs(err, ("coded", "uncoded"), 31)
    _computing_fails(monkeypatch, net)
    served = net.psfs(err, ("coded", "uncoded"), 31)
    assert all(torch.equal(served[h], fresh[h]) for h in served)
    c = 31 // 2 - 21 // 2
    assert torch.equal(net.psfs(err, ("coded",), 21)["coded"], fresh["coded"][..., c:c + 21, c:c + 21])
    with pytest.raises(AssertionError, match="rendering planes hold"):  # dropped from the store, not taken
        net.psfs(other, ("coded",), 21)


def test_planes_are_taken_only_from_a_judge_that_holds_them_all(depth_design):
    """``take_planes`` takes nothing from a judge on planes that lack one of this judge's: its PSFs are computed."""
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.judge import PSFJudge

    net = PSFJudge(depth_design, 1)
    lacking = _rendering_judge(net, net.design.depths[:2])
    err = PartErrors(mount_shift=(3e-6, -2e-6))
    lacking.psfs(err, ("coded",), 31)
    net.take_planes(lacking, lacking.source_of(err))
    assert not net._kept


@pytest.mark.parametrize("depths, refine", [([0.0, 1.0], 4), ([1.0, 2.0], 0), ([], 4), ([1.0, 2.0], 1.5)])
def test_fine_planes_refuse_what_has_no_planes_naming_a_call_that_works(depths, refine):
    from doefab.errors import DoefabError

    works = r"fine_planes\(\[1.0, 2.0\], 4\)"
    with pytest.raises(DoefabError, match=r"depths > 0 m and a whole refinement ≥ 1.*" + works):
        C.fine_planes(depths, refine)


def test_a_network_judged_depth_parts_psf_metric_computes_no_plane_again(depth_design, monkeypatch):
    """The wiring end to end, with real PSF judges: after the network judge made a depth part's rendering pair and
    the pair the network is told, the part's coded PSF at the task's kernel (what its PSF metric scores) computes
    no PSF, and is bit for bit what a judge with nothing kept computes; the network is told the same planes' PSFs."""
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.judge import PSFJudge

    base = PSFJudge(depth_design, 1)
    judge = _depth_network_judge(base)
    err = PartErrors(mount_shift=(3e-6, -2e-6), mount_rotation=0.01)
    fresh = PSFJudge(depth_design, 1).psfs(err, ("coded", "uncoded"), 63)
    rendered, told = judge.rendered_pair(err)
    assert len(rendered.depths) == 9 and told.depths == tuple(base.design.depths)
    assert torch.equal(told.coded, fresh["coded"].float()) and torch.equal(told.uncoded, fresh["uncoded"].float())
    _computing_fails(monkeypatch, base)
    assert torch.equal(base.psfs(err)["coded"], fresh["coded"])


def _depth_network_judge(base):
    """A network judge of ``base``'s design whose network's pair is on the design's planes at the task's kernel."""
    from dataclasses import dataclass

    from doefab.tolerance.netjudge import NetworkJudge

    @dataclass
    class Pair:  # the network's pair as the judge reads it: its kernel (the task's, 63 px) and its planes
        coded: torch.Tensor
        uncoded: torch.Tensor
        depths: tuple

    judge = NetworkJudge.__new__(NetworkJudge)
    judge.task, judge.base, judge._fine = "depth", base, None
    judge.rec = type("Rec", (), {"pair": Pair(torch.zeros(3, 3, 63, 63), torch.zeros(3, 3, 63, 63),
                                              tuple(base.design.depths))})()
    return judge


def test_a_height_maps_psf_metric_is_served_from_its_rendering_planes(depth_design, monkeypatch):
    """The quantization study's path: an explicit height map's rendering pair hands its planes to the design's
    judge under the height map's own source, so its PSF metric computes no PSF, bit for bit a fresh judge's."""
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.judge import PSFJudge

    base = PSFJudge(depth_design, 1)
    h = base.design.height * 0.9
    fresh = PSFJudge(depth_design, 1).height_psfs(h, ("coded",), 63)["coded"]
    _depth_network_judge(base).rendered_pair(PartErrors(), height=h)
    _computing_fails(monkeypatch, base)
    assert torch.equal(base.height_psfs(h, ("coded",), 63)["coded"], fresh)


@pytest.mark.parametrize("task, elsewhere", [("depth", True), ("hdr", False)])
def test_the_tornados_psf_pass_computes_at_the_networks_kernel_only_where_the_network_pass_takes_it_up(
        monkeypatch, task, elsewhere):
    """With ``network_top``, the PSF pass runs ``computing_at`` the network's kernel so that the network pass takes
    its coded halves up: not for depth, whose network pass renders on other planes and never reads them."""
    from contextlib import nullcontext
    from types import SimpleNamespace

    from doefab.tolerance import study
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.netjudge import NetworkJudge

    nj = NetworkJudge.__new__(NetworkJudge)
    nj.task, nj.rec = task, SimpleNamespace(pair=SimpleNamespace(coded=torch.zeros(1, 1, 95, 95)))
    entered = []
    monkeypatch.setattr(study, "network_judge_for", lambda *a, **k: nj)
    monkeypatch.setattr(study, "judge_for", lambda d, s=1: SimpleNamespace(
        computing_at=lambda k: entered.append(k) or nullcontext()))
    monkeypatch.setattr(study, "tornado_rows", lambda d, b, present, *a: [
        {"error": k.name, "delta": float(i)} for i, k in enumerate(present)])
    rows = study.tornado("design", load_budget(None), networks=True, network_top=2, progress=False)
    assert rows and entered == ([] if elsewhere else [95])
