"""``doefab doctor`` checks exactly what ``doefab run`` and ``run --quick`` will do with a scene's design grid:
a ``design.sampling`` that does not divide the DOE grid is refused by the doctor (not first by the design stage),
and ``--quick`` coarsens the grid only by a factor that divides it (a sweep of lenses, apertures and pitches)."""

import itertools
import math
import re

import pytest

from doefab.design.optimize import design_camera as optimiser_camera
from doefab.errors import DoefabError
from doefab.pipeline.scene import load_scene
from doefab.pipeline.stages import _design_run, quick_sampling
from doefab.optics import psf as psf_module
from doefab.pipeline import system
from doefab.pipeline.system import design_camera, resolve


def _scene(tmp_path, focal_mm, f_number, pitch_um, sampling=None):
    design = "" if sampling is None else f"[design]\nsampling = {sampling}\n"
    p = tmp_path / f"s_{focal_mm}_{f_number}_{pitch_um}_{sampling}.toml"
    p.write_text(f'task = "hdr"\nstages = ["design"]\n[camera]\nfocal_length_mm = {focal_mm}\nf_number = {f_number}\n'
                 f"doe_pitch_um = {pitch_um}\n{design}")
    return load_scene(p)


def _grid(focal_mm, f_number, pitch_um, focus_m=5.0):
    """The DOE grid the scene implies, computed here: the aperture over the pitch, rounded up to even."""
    s = 1 / (1 / (focal_mm * 1e-3) - 1 / focus_m)
    aperture = 1 / (1 / s + 1 / focus_m) / f_number
    return 2 * math.ceil(aperture / (pitch_um * 1e-6) / 2 - 1e-9)


SWEEP = list(itertools.product((25.0, 35.0, 50.0), (2.8, 4.0, 5.6), (4.0, 5.4, 8.0), (None, 3, 4)))


@pytest.mark.parametrize("focal_mm,f_number,pitch_um,sampling", SWEEP)
def test_doctor_refuses_what_the_design_stage_would(tmp_path, focal_mm, f_number, pitch_um, sampling):
    scene = _scene(tmp_path, focal_mm, f_number, pitch_um, sampling)
    grid = _grid(focal_mm, f_number, pitch_um)
    divides = sampling is None or grid % sampling == 0  # the hdr design's own sampling (2) divides any even grid
    try:
        res = resolve(scene)
    except DoefabError as exc:
        assert ("must divide the DOE grid" in str(exc)) == (not divides), str(exc)
        if not divides:
            assert f"({grid} px)" in str(exc) and "design.sampling" in str(exc)
        return
    assert divides, f"doctor passed sampling {sampling} on a {grid}-px grid"
    assert res.camera.doe_pixels == grid
    for quick in (False, True):  # what the design stage hands the optimiser, run and run --quick
        iters, used = _design_run(res.settings, quick, res.quick_sampling)
        cam = optimiser_camera(res.camera, used)  # the optimiser's own check: raises if it does not divide
        assert cam.doe_pixels * used == grid


def test_quick_sampling_picks_a_factor_that_divides():
    assert quick_sampling(3200, 1) == 4 and quick_sampling(3200, 2) == 4
    assert quick_sampling(2234, 1) == 2  # 2234 = 2 · 1117: 4 would not divide it
    assert quick_sampling(2190, 1) == 5 and quick_sampling(2190, 2) == 6  # 2190 = 2 · 3 · 5 · 73; ties: larger
    assert quick_sampling(2188, 2) == 4
    assert quick_sampling(1000, 3) == 3  # nothing in 3..8 that divides 1000 and is a multiple of 3
    for grid in range(100, 3000, 2):
        for s in (1, 2, 4):
            if grid % s:
                continue  # a scene sampling that does not divide the grid is refused before any run
            q = quick_sampling(grid, s)
            assert grid % q == 0 and q % s == 0 and q <= max(8, s)


def test_issue_camera_doctor_and_quick_run_agree(tmp_path):
    """The trial's lens: 25 mm f/2.8 with a 4 µm DOE pitch gives a 2234-px grid; doctor names the sampling a
    scene sets when it cannot divide it, and the quick run's coarsening divides it."""
    grid = _grid(25.0, 2.8, 4.0)
    assert grid == 2234
    with pytest.raises(DoefabError, match=r"design.sampling 4 must divide the DOE grid \(2234 px\): use 1 or 2"):
        resolve(_scene(tmp_path, 25.0, 2.8, 4.0, 4))
    res = resolve(_scene(tmp_path, 25.0, 2.8, 4.0))
    assert _design_run(res.settings, True, res.quick_sampling)[1] == 2


def test_the_die_holds_the_pattern_and_marks_and_no_smaller_one_does(tmp_path, tiny_camera):
    """``smallest_die_m`` against the mask export's own checks: the export accepts the die it names and refuses
    one a millimetre smaller (the 12 mm floor lifted, so the bound is the pattern's and the marks')."""
    import numpy as np

    from doefab.fabrication.export import LevelMap, MaskOptions, export_masks
    from doefab.fabrication.marks import smallest_die_m

    cam = tiny_camera
    die = smallest_die_m(cam.aperture_diameter, cam.doe_pixels * cam.doe_pitch, cam.doe_pitch, 2, floor_m=0.0)
    levels = np.full((cam.doe_pixels, cam.doe_pixels), 3, np.uint8)
    levels[:, : cam.doe_pixels // 2] = np.arange(cam.doe_pixels // 2) % 4
    export_masks(LevelMap(levels, cam, n_levels=4), tmp_path / "ok", MaskOptions(die_m=die, use_klayout=False))
    with pytest.raises(DoefabError, match="die"):
        export_masks(LevelMap(levels, cam, n_levels=4), tmp_path / "small",
                     MaskOptions(die_m=die - 1e-3, use_klayout=False))


def test_a_large_aperture_gets_a_die_and_holder_of_its_own(tmp_path):
    """A 50 mm f/2.8 lens: a 17.86 mm DOE needs a 21 mm die (the prototype's 12 mm cannot hold it; the marks
    need 17.86 + 2 mm, the holder's pocket 17.86 + 2 · (1.2 mm ledge + 0.3 mm margin) = 20.86 mm); the holder the
    run builds takes that die and the DOE's clear aperture, and a thread too small for it is named by doctor."""
    from holder_cad.params import HolderParams

    from doefab.pipeline.system import scene_holder

    p = tmp_path / "big.toml"
    p.write_text('task = "hdr"\nstages = ["design", "masks", "holder"]\n[camera]\nfocal_length_mm = 50.0\n'
                 'f_number = 2.8\ndoe_pitch_um = 8.0\n[holder]\nthread_diameter_mm = 62\n')
    res = resolve(load_scene(p))
    aperture = res.camera.aperture_diameter
    assert 17.5e-3 < aperture < 18e-3 and res.die_m == pytest.approx(21e-3)
    params = scene_holder(load_scene(p))
    assert params["die_width_mm"] == 21.0 and params["clear_aperture_mm"] == pytest.approx(aperture * 1e3)
    HolderParams(**params)
    p.write_text(p.read_text().replace("thread_diameter_mm = 62", "thread_diameter_mm = 30.5"))
    with pytest.raises(DoefabError, match="holder: .*thread_diameter_mm"):
        resolve(load_scene(p))


@pytest.mark.parametrize("holder, needle, works", [
    ("die_width_mm = 10\ndie_height_mm = 10", "square die of at least 12 mm", "die_width_mm = 12\ndie_height_mm = 12"),
    ("die_width_mm = 14\ndie_height_mm = 12", "set both to 14", "die_width_mm = 14\ndie_height_mm = 14"),
    ("clear_aperture_mm = 5", "smaller than the DOE's clear aperture (8.929 mm)", "clear_aperture_mm = 8.93"),
])
def test_a_holder_that_disagrees_with_the_doe_is_refused_with_a_value_that_works(tmp_path, holder, needle, works):
    """The 25 mm f/2.8 lens of the trial (an 8.93 mm DOE): a die smaller than the mask set's, a die that is not
    square, a hole that would clip the DOE — each refused by doctor with a value that then passes; a larger
    square die is taken by the mask set too."""
    base = 'task = "hdr"\nstages = ["design", "masks", "holder"]\n[camera]\nfocal_length_mm = 25.0\n' \
           'f_number = 2.8\ndoe_pitch_um = 4.0\n[holder]\nthread_diameter_mm = 52\n'
    p = tmp_path / "h.toml"
    p.write_text(base + holder + "\n")
    with pytest.raises(DoefabError, match=re.escape(needle)):
        resolve(load_scene(p))
    p.write_text(base + works + "\n")
    res = resolve(load_scene(p))
    if "die_width_mm = 14" in works:
        assert res.die_m == pytest.approx(14e-3)


def _design_grids_accept(res) -> list[str]:
    """Which of the grids the design stage computes PSFs on (full, the run's, the quick run's) the PSF route itself
    refuses (``PSFPlan`` raises SamplingError): the independent oracle for what doctor must catch."""
    import doefab
    from doefab.errors import SamplingError

    task, cam = res.task, res.camera
    refused = []
    for name, factor in (("full", 1), ("run", _design_run(res.settings, False)[1]),
                         ("quick", _design_run(res.settings, True, res.quick_sampling)[1])):
        try:
            doefab.PSFPlan(design_camera(cam, factor), task.wavelengths(cam), task.depths(cam), task.kernel_size)
        except SamplingError as exc:
            refused.append(f"{name} ({factor}): {exc}")
    return refused


def _depth_scene(tmp_path, near, pitch_um=None, sampling=None):
    cam = "" if pitch_um is None else f"[camera]\ndoe_pitch_um = {pitch_um}\n"
    des = "" if sampling is None else f"[design]\nsampling = {sampling}\n"
    p = tmp_path / f"d_{near}_{pitch_um}_{sampling}.toml"
    p.write_text(f'task = "depth"\nstages = ["design"]\n{cam}[optics]\ndepths_m = [{near}, 1.5, 2.0, 3.0]\n{des}')
    return p


DEPTH_SWEEP = list(itertools.product((0.12, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0), (None, 4.0, 8.0), (None, 1, 4)))


@pytest.mark.parametrize("near,pitch_um,sampling", DEPTH_SWEEP)
def test_doctor_passes_only_what_every_design_grid_can_sample(tmp_path, monkeypatch, near, pitch_um, sampling):
    """Depth scenes with near planes, other pitches and design samplings: when doctor passes, the PSF route accepts
    the full grid, the run's design grid and the quick run's; when doctor refuses for sampling, its first
    suggested fix, applied, passes doctor and every grid the route computes. (The window's own check, which
    refuses these near planes' defocus blur in the 63 px window, is left out here: test_window_blur.py.)"""
    monkeypatch.setattr(system, "window_blur_checks", lambda *args: [])
    monkeypatch.setattr(psf_module, "_check_window", lambda *args: None)  # the API's, the same rule
    path = _depth_scene(tmp_path, near, pitch_um, sampling)
    try:
        res = resolve(load_scene(path))
    except DoefabError as exc:
        msg = str(exc)
        if "must divide" in msg or ("phase" not in msg and "alias" not in msg):
            return  # refused for another reason (tested elsewhere)
        fix = re.search(r"set (design.sampling = \d+|a nearest depth ≥ [\d.]+ m)", msg)
        assert fix, msg
        fixed = (_depth_scene(tmp_path, float(fix[1].split("≥ ")[1][:-2]), pitch_um, sampling)
                 if "depth" in fix[1] else _depth_scene(tmp_path, near, pitch_um, int(fix[1].split("= ")[1])))
        assert not _design_grids_accept(resolve(load_scene(fixed))), (msg, fix[1])
        return
    assert not _design_grids_accept(res), near


def _far_scene(tmp_path, far, pitch_um):
    p = tmp_path / f"far_{far}_{pitch_um}.toml"
    p.write_text(f'task = "depth"\nstages = ["design"]\n[camera]\nfocus_distance_m = 0.6\ndoe_pitch_um = {pitch_um}\n'
                 f'[optics]\ndepths_m = [0.6, 1.0, {far}]\n[design]\nsampling = 1\n')
    return p


@pytest.mark.parametrize("far,pitch_um", list(itertools.product((2.0, 5.0, 20.0, 100.0), (8.0, 16.0, 24.0))))
def test_a_far_plane_beyond_a_near_focus_is_checked_too(tmp_path, monkeypatch, far, pitch_um):
    """A camera focused at 0.6 m with planes out to ``far``: the farthest plane's wavefront is the steepest (a
    point beyond the focus converges behind the sensor). Doctor passes only what the PSF route samples on every
    design grid, and its suggested farthest depth, applied, passes both."""
    monkeypatch.setattr(system, "window_blur_checks", lambda *args: [])
    monkeypatch.setattr(psf_module, "_check_window", lambda *args: None)
    try:
        res = resolve(load_scene(_far_scene(tmp_path, far, pitch_um)))
    except DoefabError as exc:
        msg = str(exc)
        assert "phase" in msg, msg
        fix = re.search(r"a farthest depth ≤ ([\d.]+) m", msg)
        assert fix, msg
        assert float(fix[1]) < far
        assert not _design_grids_accept(resolve(load_scene(_far_scene(tmp_path, float(fix[1]), pitch_um)))), msg
        return
    assert not _design_grids_accept(res), (far, pitch_um)


@pytest.mark.parametrize("near_m, inside", [(0.004, True), (0.0042, True), (0.0044, False), (0.3, False)])
def test_a_plane_within_the_focal_length_is_named(tmp_path, near_m, inside):
    """A 4.3 mm phone lens focused at 1 m: a plane nearer than 4.3 mm forms no real image (1/s = 1/f − 1/z < 0),
    and the refusal says so, not that its blur is too wide."""
    p = tmp_path / "phone.toml"
    p.write_text('task = "depth"\nstages = ["design"]\n[camera]\nfocal_length_mm = 4.3\nf_number = 1.8\n'
                 'lens_f_number = 1.8\nfocus_distance_m = 1.0\nsensor_pitch_um = 1.0\ndoe_pitch_um = 1.0\n'
                 f'[optics]\ndepths_m = [{near_m}, 0.5, 1.0]\n')
    try:
        resolve(load_scene(p))
    except DoefabError as exc:
        named = f"{near_m:g} m lies within the lens's focal length (4.3 mm)" in str(exc)
        assert named == inside and (not inside or "1 problem(s)" in str(exc)), str(exc)
    else:
        assert not inside
