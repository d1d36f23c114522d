"""Rigid mounting errors are modelled exactly: a decenter moves the relief and its baffle against the lens and
the split without resampling them; a rotation turns the relief by band-limited interpolation (issue 22)."""

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

import doefab
from doefab.design.design import Design
from doefab.optics.propagators import make_route
from doefab.optics.propagators.base import FocalSetup
from doefab.optics.pupil import cell_coverage
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

PITCH = 5.4e-6
N = 240  # a 1.3 mm aperture: Airy radius ~2 sensor px at 50 mm, so a 3×3 box holds most of a spot


@pytest.fixture(scope="module")
def grating_dir(grating_design):
    """A quantized blazed grating (Λ = 16 px) over the coded half, 3 bands, the grating task's metric."""
    return grating_design(N, 161, seed=0)


@pytest.fixture(scope="module")
def judges(grating_dir):
    return {s: PSFJudge(grating_dir, s, margin=30 * PITCH) for s in (1, 2)}


def _moved_pattern_psf(judge, n: int) -> torch.Tensor:
    """Independent route: the die drawn on a lens-centred grid with its levels moved n whole pixels to +x and its
    baffle centred on them; the split line stays at x = 0. No relief resampling anywhere."""
    d = judge.design
    cam = d.camera
    a, radius = cam.doe_pitch, cam.aperture_diameter / 2
    width = N + 2 * n
    x = (np.arange(width) - (width - 1) / 2) * a  # lens frame
    y = -((np.arange(N) - (N - 1) / 2) * a)
    levels = np.full((N, width), 15, np.uint8)
    levels[:, 2 * n:] = d.levels  # die column j sits at lens x = (j − (N − 1)/2)·a + n·a
    cov = cell_coverage(x - n * a, y, a, radius, -1, -n * a)  # disk around the die centre, split at lens x = 0
    keep = cov.any(axis=0)
    h = doefab.levels_to_height(levels, cam)[:, keep] - 15 * doefab.level_step(cam)
    route = make_route("spectral")
    out = []
    for i, lam in enumerate(d.wavelengths):
        setup = FocalSetup(x[keep], y, a, True, d.wavelengths, cam.sensor_distance, cam.sensor_pitch,
                           judge.task.kernel_size, (0.0, 0.0), torch.float32, None)
        phase = torch.from_numpy(2 * math.pi / lam * (float(cam.material.index(lam)) - 1) * h).float()
        pupil = torch.from_numpy(cov[:, keep]).float() * torch.polar(torch.ones_like(phase), phase)
        full_area = float(cell_coverage(x - n * a, y, a, radius, 0).sum() * a * a)
        out.append(route.intensity(pupil, i, setup, route.prepare(setup)) / full_area)
    return torch.stack(out)[None]


@pytest.mark.parametrize("n", [3, 11])
def test_whole_pixel_decenter_is_the_pattern_moved_by_whole_pixels(judges, n):
    j = judges[1]
    got = j.psfs(PartErrors(mount_shift=(n * PITCH, 0.0)))["coded"]
    ref = _moved_pattern_psf(j, n)
    assert float((got - ref).abs().max()) <= 1e-5 * float(ref.max())  # float32 rounding of two FFT sizes
    assert float((got - j.nominal.float()).abs().max()) > 1e-3 * float(ref.max())  # and it did move


def test_sub_pixel_decenter_lies_between_its_whole_pixel_neighbours(judges):
    j = judges[1]
    m = {v: j.evaluate(PartErrors(mount_shift=(v * PITCH, 0.0)))["metric"] for v in (6, 6.25, 6.5, 6.75, 7)}
    lo, hi = sorted((m[6], m[7]))
    assert all(lo <= m[v] <= hi for v in (6.25, 6.5, 6.75))
    assert m[6] > m[6.25] > m[6.5] > m[6.75] > m[7]  # light moves steadily out of the coded half


def test_decenter_along_the_split_moves_nothing_in_focus(judges):
    """A point in focus has a flat wavefront: sliding the die along the split line only shifts the pupil."""
    j = judges[1]
    r = j.evaluate(PartErrors(mount_shift=(0.0, 17.3 * PITCH)))
    assert r["l1_to_nominal"] < 1e-5


def test_mount_sweeps_are_monotone(judges):
    j = judges[1]
    across = [j.evaluate(PartErrors(mount_shift=(v * PITCH, 0.0)))["metric"] for v in (0, 4, 6.5, 8, 12.5, 16, 24)]
    turned = [j.evaluate(PartErrors(mount_rotation=math.radians(v)))["metric"] for v in (0, 0.5, 0.75, 1, 2, 4)]
    assert all(a > b for a, b in zip(across, across[1:])), across
    assert all(a > b for a, b in zip(turned, turned[1:])), turned


@pytest.mark.parametrize("err", [PartErrors(mount_shift=(7.4 * PITCH, 0.0)),
                                 PartErrors(mount_rotation=math.radians(0.6)),
                                 PartErrors(mount_rotation=math.radians(2.0), mount_shift=(-3.3 * PITCH, 2e-6))])
def test_default_grid_agrees_with_a_twice_finer_one(judges, err):
    """Within 1e-3 of the metric (the issue asks 0.005 of the committed design; a relief resampled bilinearly
    by a sub-pixel decenter misses by 4e-3 on this one)."""
    one, two = (judges[s].evaluate(err)["metric"] for s in (1, 2))
    nominal_shift = judges[1].score(judges[1].nominal)["metric"] - judges[2].score(judges[2].nominal)["metric"]
    assert abs(one - two) <= 1e-3 and abs(nominal_shift) < 1e-4


def test_a_rotation_turns_the_first_order_spot(judges):
    """The first order lands at s·λ/Λ along the grating vector; turning the die by θ turns the spot by θ about
    the axis (its centroid, read off the PSF, follows to a tenth of a pixel)."""
    j = judges[2]
    th = math.radians(3.0)
    psf = j.psfs(PartErrors(mount_rotation=th))["coded"][0, 2].double()
    k = psf.shape[-1]
    c = k // 2
    spot = j.task.spot_pixels(j.fine)[2]
    rows, cols = torch.meshgrid(torch.arange(k, dtype=torch.float64), torch.arange(k, dtype=torch.float64),
                                indexing="ij")
    box = ((cols - c - spot).abs() <= 8) & ((rows - c + spot * math.sin(th)).abs() <= 8)
    w = psf * box
    x = float((w * (cols - c)).sum() / w.sum())
    y = float((w * (c - rows)).sum() / w.sum())
    assert math.degrees(math.atan2(y, x)) == pytest.approx(3.0, abs=math.degrees(0.1 / spot))


def test_stop_decides_whether_the_gap_matters(grating_dir):
    """The prototype's baffle (f/1.8 lens) is the stop: a gap moves nothing. A lens stopped down below the
    baffle makes the DOE sit in front of the stop: the gap now blurs and leaks."""
    j = PSFJudge(grating_dir, 1)
    assert j.fine.doe_is_stop and j.evaluate(PartErrors(axial_gap=5e-3))["l1_to_nominal"] == 0.0
    d = Design.load(grating_dir)
    small = replace(d, camera=d.camera.replace(lens_f_number=60.0))  # 0.8 mm entrance pupil < 1.3 mm baffle
    other = grating_dir.parent / "lens_stop"
    small.save(other)
    k = PSFJudge(other, 1)
    l1 = [k.evaluate(PartErrors(axial_gap=g))["l1_to_nominal"] for g in (0.0, 1e-3, 5e-3)]
    assert not k.fine.doe_is_stop and l1[0] == 0.0 and 0 < l1[1] < l1[2]


def test_a_vanishing_gap_changes_nothing_in_front_of_a_lens_stop(grating_dir):
    """DOE in front of the lens's stop: propagating a relief that varies along both axes over 1 nm must leave
    its PSF as without the gap (the whole window is carried over the gap, not one of its rows)."""
    d = Design.load(grating_dir)
    lv = d.levels.copy()
    lv[::3, : N // 2] = (lv[::3, : N // 2] + 7) % 16  # rows now differ
    other = grating_dir.parent / "lens_stop_rows"
    replace(d, camera=d.camera.replace(lens_f_number=60.0), levels=lv,
            height=doefab.levels_to_height(lv, d.camera)).save(other)
    k = PSFJudge(other, 1)
    assert not k.fine.doe_is_stop
    with torch.no_grad():
        none, tiny = (k.psfs(PartErrors(axial_gap=g))["coded"] for g in (0.0, 1e-9))
    assert float((tiny - none).abs().max()) <= 1e-4 * float(none.max())


def test_planes_in_batches_equal_each_plane_alone(grating_dir, monkeypatch):
    """A part's PSFs at several depths, transformed a few planes at a time (``plane_batches``), equal each depth
    computed by a judge of that depth alone (defocus, a decenter across the split and one along it)."""
    from doefab.tolerance import mounted

    d = Design.load(grating_dir)
    depths = (0.6, 1.0, 2.0, 3.5, 9.0)
    err = PartErrors(mount_shift=(2.6 * PITCH, 1.3 * PITCH))
    halves = ("coded", "uncoded")
    alone = torch.cat([PSFJudge(replace(d, depths=(z,)), 1, margin=30 * PITCH).psfs(err, halves)["coded"]
                       for z in depths])
    for per_run in (1, 2):  # one plane per transform, and runs of two with a remainder
        monkeypatch.setattr(mounted, "plane_batches",
                            lambda n, _, k=per_run: [slice(j, min(j + k, n)) for j in range(0, n, k)])
        got = PSFJudge(replace(d, depths=depths), 1, margin=30 * PITCH).psfs(err, halves)
        assert got["coded"].shape == alone.shape
        assert float((got["coded"] - alone).abs().max()) <= 1e-6 * float(alone.max())
        assert float((got["coded"][0] - got["coded"][-1]).abs().max()) > 1e-2 * float(alone.max())  # defocus shows
