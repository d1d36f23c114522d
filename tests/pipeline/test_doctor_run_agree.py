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

    from doefab.pipeline.sceneholder import scene_holder

    p = tmp_path / "big.toml"
    p.write_text('task = "hdr"\nstages = ["design", "masks", "holder"]\n[camera]\nfocal_length_mm = 50.0\n'
                 'f_number = 2.8\ndoe_pitch_um = 8.0\n[holder]\nthread_diameter_mm = 62\n')
    res = resolve(load_scene(p))
    aperture = res.camera.aperture_diameter
    assert 17.5e-3 < aperture < 18e-3 and res.die_m == pytest.approx(21e-3)
    params = scene_holder(load_scene(p), res.camera)
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
        assert named == inside and (not inside or "1 problem" in str(exc)), str(exc)
    else:
        assert not inside


_PHONE = ('task = "depth"\nstages = ["design"]\n[camera]\nfocal_length_mm = 4.3\nf_number = 1.8\nlens_f_number = 1.8\n'
          'focus_distance_m = 1.0\nsensor_pitch_um = 1.0\ndoe_pitch_um = {pitch}\n[optics]\n'
          'depths_m = [{near}, 0.5, 1.0, 2.0, 4.0]\n[design]\nsampling = {sampling}\nparameterization = "radial"\n')


@pytest.mark.parametrize("pitch, sampling", [(30.0, 2), (21.6, 2), (12.0, 4)])
def test_every_fix_named_for_a_coarse_design_grid_passes(tmp_path, pitch, sampling):
    """A 4.3 mm f/1.8 phone lens on 1 µm pixels whose design grid is too coarse twice over (the nearest plane's
    phase step and the window beyond the alias-free field): each fix the refusal names, applied alone, passes
    (a nearer-plane fix alone would leave the window beyond the field, and a pitch must fix both)."""
    p = tmp_path / "s.toml"
    p.write_text(_PHONE.format(pitch=pitch, near=0.3, sampling=sampling))
    with pytest.raises(DoefabError) as exc:
        resolve(load_scene(p))
    msg = str(exc.value)
    assert "alias-free field" in msg and "set " in msg, msg
    fixes = msg.split(": set ")[-1].split(" or ")
    assert len(fixes) >= 2, msg
    for fix in fixes:
        if fix.startswith("design.sampling = "):
            kw = dict(pitch=pitch, near=0.3, sampling=int(fix.split("= ")[1].split()[0]))
        elif fix.startswith("camera.doe_pitch_um ≤ "):
            kw = dict(pitch=float(fix.split("≤ ")[1]), near=0.3, sampling=sampling)
        else:
            raise AssertionError(f"a fix this test does not know: {fix!r} ({msg})")
        p.write_text(_PHONE.format(**kw))
        resolve(load_scene(p))  # passes


def test_a_window_beyond_the_alias_free_field_is_told_values_that_fix_it(tmp_path):
    """The phone lens on 50 µm DOE pixels: a 63 px window reaches beyond the field the sampling leaves
    (λ·s / (2·p) / pixel = 486 nm · 4.32 mm / 100 µm / 1 µm ≈ 21 px each way); the refusal names a window and a
    pitch, and each, applied, clears that problem."""
    p = tmp_path / "s.toml"
    text = _PHONE.format(pitch=50.0, near=0.6, sampling=1)
    p.write_text(text)
    with pytest.raises(DoefabError) as exc:
        resolve(load_scene(p))
    m = re.search(r"alias-free field \((\d+) px at 486 nm\): set optics.kernel_px ≤ (\d+) or camera.doe_pitch_um ≤ "
                  r"([\d.]+)", str(exc.value))
    assert m, str(exc.value)
    field = 486e-9 * 4.3e-3 / (1 - 4.3e-3) / (2 * 50e-6) / 1e-6  # px, s = f / (1 − f / z) at z = 1 m
    assert int(m[1]) == round(2 * field - 1)
    k = int(m[2]) - (int(m[2]) + 1) % 2  # the largest odd window within the bound
    for fixed in (text.replace("[optics]\n", f"[optics]\nkernel_px = {k}\n"),
                  text.replace("doe_pitch_um = 50.0", f"doe_pitch_um = {m[3]}")):
        p.write_text(fixed)
        try:
            resolve(load_scene(p))
        except DoefabError as left:
            assert "alias-free field" not in str(left), str(left)


def test_depth_planes_with_no_depth_cue_and_a_capped_ring_are_warned(tmp_path):
    """Millimetres typed into depths_m (300, 500, 1000 m): the phone lens's plain-half blur changes by
    D·s·|1/300 − 1/1000| / 2 / 1 µm ≈ 0.01 px across them, a warning that names metres. On the phone lens with
    planes 0.3–4 m the defocus blur at 0.3 m is ≈ 17 px, which a 31 px window caps: warned, with the window that
    holds it."""
    p = tmp_path / "s.toml"
    p.write_text(_PHONE.format(pitch=1.0, near=0.3, sampling=1).replace("depths_m = [0.3, 0.5, 1.0, 2.0, 4.0]",
                                                                          "depths_m = [300.0, 500.0, 1000.0]"))
    warnings = resolve(load_scene(p)).warnings
    assert any("300–1000 m" in w and "no depth cue" in w and "metres" in w for w in warnings), warnings
    p.write_text(_PHONE.format(pitch=1.0, near=0.3, sampling=1).replace("[optics]\n", "[optics]\nkernel_px = 31\n"))
    res = resolve(load_scene(p))
    cam = res.camera
    r = cam.aperture_diameter * cam.sensor_distance * (1 / 0.3 - 1 / 4.0) / 2 / cam.sensor_pitch
    capped = [w for w in res.warnings if w.startswith("design.ring_max_px")]
    assert len(capped) == 1 and f"{r:.1f} px, is capped to 12 px" in capped[0], res.warnings
    k = int(re.search(r"optics.kernel_px ≥ (\d+)", capped[0])[1])
    p.write_text(_PHONE.format(pitch=1.0, near=0.3, sampling=1).replace("[optics]\n", f"[optics]\nkernel_px = {k}\n"))
    assert not any(w.startswith("design.ring_max_px") for w in resolve(load_scene(p)).warnings)


@pytest.mark.parametrize("bands, warned", [("[1000, 900, 800]", True), ("[650, 550, 450]", False)])
def test_rgb_bands_a_colour_camera_does_not_see_are_warned(tmp_path, bands, warned):
    """A depth design takes its three bands as the camera's R, G and B channels: bands in the near infrared, beyond
    the default camera's measured 380–780 nm response, are warned; visible ones are not."""
    p = tmp_path / "s.toml"
    p.write_text(f'task = "depth"\nstages = ["design"]\n[optics]\nwavelengths_nm = {bands}\n')
    notes = [w for w in resolve(load_scene(p)).warnings if w.startswith("optics.wavelengths_nm")]
    assert bool(notes) == warned, notes
    if warned:
        assert "1000, 900, 800 nm lie outside" in notes[0] and "380–780 nm" in notes[0]


def test_planes_too_steep_on_both_sides_of_the_focus_are_told_both_bounds(tmp_path, monkeypatch):
    """Focused at 0.6 m on 24 µm DOE pixels with planes at 0.3 m and 100 m: both wavefronts are too steep (about 2.4
    rad per pixel each), so the depth fix must move both planes (a nearest and a farthest depth, together); it and
    the pitch fix each pass doctor and the PSF route."""
    monkeypatch.setattr(system, "window_blur_checks", lambda *args: [])
    monkeypatch.setattr(psf_module, "_check_window", lambda *args: None)

    def scene(depths, pitch=24.0):
        p = tmp_path / "s.toml"
        p.write_text(f'task = "depth"\nstages = ["design"]\n[camera]\nfocus_distance_m = 0.6\ndoe_pitch_um = {pitch}\n'
                     f'[optics]\ndepths_m = {depths}\n[design]\nsampling = 1\n')
        return load_scene(p)
    with pytest.raises(DoefabError) as exc:
        resolve(scene([0.3, 1.0, 100.0]))
    m = re.search(r"a nearest depth ≥ ([\d.]+) m and a farthest depth ≤ ([\d.]+) m \(optics.depths_m\) or "
                  r"camera.doe_pitch_um ≤ ([\d.]+)", str(exc.value))
    assert m, str(exc.value)
    near, far = float(m[1]), float(m[2])
    assert 0.3 < near < 0.6 < far < 100
    assert not _design_grids_accept(resolve(scene([near, 1.0, far])))
    assert not _design_grids_accept(resolve(scene([0.3, 1.0, 100.0], float(m[3]))))


def test_a_steep_plane_on_a_coarsened_design_grid_names_the_fix_for_each_grid(tmp_path, monkeypatch):
    """85 mm f/1.4 focused at 3 m on 10 µm DOE pixels, a plane at 1 m: 2.6 rad per DOE pixel on the full grid, four
    times that on the design grid of design.sampling 4. The message gives the design grid's depth bound (saying
    so) and the full grid's with design.sampling = 1; each passes doctor and the PSF route on its grids."""
    monkeypatch.setattr(system, "window_blur_checks", lambda *args: [])
    monkeypatch.setattr(psf_module, "_check_window", lambda *args: None)

    def scene(near, sampling):
        p = tmp_path / "s.toml"
        p.write_text(f'task = "depth"\nstages = ["design"]\n[camera]\nfocal_length_mm = 85.0\nf_number = 1.4\n'
                     f'lens_f_number = 1.4\nfocus_distance_m = 3.0\ndoe_pitch_um = 10.0\nsensor_pitch_um = 5.9\n'
                     f'[optics]\ndepths_m = [{near}, 3.0]\n[design]\nsampling = {sampling}\n')
        return load_scene(p)
    with pytest.raises(DoefabError) as exc:
        resolve(scene(1.0, 4))
    msg = str(exc.value)
    m = re.search(r"a nearest depth ≥ ([\d.]+) m \(optics.depths_m\)[^,]* \(for the design grid, \d+ px at "
                  r"design.sampling 4\), or design.sampling = 1 with a nearest depth ≥ ([\d.]+) m", msg)
    assert m, msg
    coarse, full = float(m[1]), float(m[2])
    assert 1.0 < full < coarse < 3.0
    assert not _design_grids_accept(resolve(scene(coarse, 4)))
    assert not _design_grids_accept(resolve(scene(full, 1)))
    with pytest.raises(DoefabError):
        resolve(scene(full, 4))  # the full grid's bound is not enough for the design grid's


def test_a_window_beyond_the_full_grids_field_is_one_problem_not_a_second_telling_the_sampling_it_has(tmp_path):
    """60 µm DOE pixels leave a 74 px alias-free field at 486 nm (λ·s / (2·b) / p): a 95 px window is refused once,
    by the DOE grid's own check, not again as a design grid of design.sampling 1 told to set design.sampling = 1."""
    p = tmp_path / "s.toml"
    p.write_text('task = "hdr"\nstages = ["design"]\n[camera]\ndoe_pitch_um = 60.0\n[optics]\nkernel_px = 95\n'
                 '[design]\nsampling = 1\n')
    with pytest.raises(DoefabError) as exc:
        resolve(load_scene(p))
    msg = str(exc.value)
    assert "1 problem: optics.kernel_px 95 reaches beyond the DOE sampling's alias-free field (74 px" in msg, msg
    assert "design.sampling = 1" not in msg


def test_a_small_doe_takes_a_die_smaller_than_the_prototypes_down_to_what_it_needs(tmp_path):
    """A 16 mm f/2.8 lens: a 5.71 mm DOE. Its marks need 5.72 + 2 mm (8 mm), the holder's pocket 5.71 + 3 mm (9 mm):
    a mask set may be drawn on a 9 mm die (the default stays the prototype's 12 mm), not on 8 mm; with a holder
    stage the least die is the one whose washers the holder takes too, and that one passes; a die key's chamfer
    must stay below half the die."""
    base = ('task = "hdr"\nstages = ["design", "masks"]\n[camera]\nfocal_length_mm = 16.0\nf_number = 2.8\n'
            'lens_f_number = 2.8\nsensor_pitch_um = 3.45\ndoe_pitch_um = 4.0\n[holder]\nthread_diameter_mm = 40.5\n')
    p = tmp_path / "s.toml"
    p.write_text(base)
    assert resolve(load_scene(p)).die_m == pytest.approx(12e-3)
    p.write_text(base + "die_width_mm = 9\ndie_height_mm = 9\n")
    assert resolve(load_scene(p)).die_m == pytest.approx(9e-3)
    p.write_text(base + "die_width_mm = 8\ndie_height_mm = 8\n")
    with pytest.raises(DoefabError, match=r"square die of at least 9 mm .*set both to 9.*follow the DOE: 12 mm"):
        resolve(load_scene(p))
    p.write_text(base + "die_width_mm = 9\ndie_height_mm = 9\ndie_chamfer_mm = 4.5\n")
    with pytest.raises(DoefabError, match=r"holder.die_chamfer_mm: die chamfer 4.5 mm must be below half the die"):
        resolve(load_scene(p))
    holder = base.replace('"masks"]', '"masks", "holder"]')
    p.write_text(holder + "die_width_mm = 8\ndie_height_mm = 8\n")
    with pytest.raises(DoefabError) as exc:
        resolve(load_scene(p))
    least = int(re.search(r"square die of at least (\d+) mm", str(exc.value))[1])
    assert least >= 9
    p.write_text(holder + f"die_width_mm = {least}\ndie_height_mm = {least}\n")
    assert resolve(load_scene(p)).die_m == pytest.approx(least * 1e-3)
    if least > 9:
        p.write_text(holder + f"die_width_mm = {least - 1}\ndie_height_mm = {least - 1}\n")
        with pytest.raises(DoefabError):
            resolve(load_scene(p))
