"""What a scene's system gets warned about (it works, but deserves the user's eye), and the depth planes' blur span
that the scene checks share: bands or a design wavelength where the substrate's dispersion is extrapolated or far
from the bands, a diffraction blur wider than the task's metric, an RGB task's bands outside the camera's colours,
depth planes with no depth cue, a default ring capped by its window. Each function returns its warnings, one
string each, naming the key and what to do."""

from __future__ import annotations

import math

from doefab.applications import has
from doefab.pipeline.scene import Scene

__all__ = ["depth_span_px", "system_warnings", "design_grid_notes", "sensor_warnings", "depth_warnings", "band_warnings", "DATA_STEP_M",
           "MIN_WAVES"]

MIN_WAVES = 0.75  # the least of a wave the relief's full depth may give the longest band without a warning
MAX_WAVES = 2.0  # the most waves it may give the shortest band (the paper's 550 nm design gives 400 nm 1.4)
DATA_STEP_M = 10e-9  # the hyperspectral scenes' measured spectra: every 10 nm (``reconstruction.bands``)


def depth_span_px(cam, planes) -> float:
    """The half aperture's geometric blur radius (sensor px) at the nearest of ``planes`` (metres) when it is
    sharp at the farthest, D·s·|1/z_near − 1/z_far| / 2: how much the planes' blurs differ."""
    near, far = min(planes), max(planes)
    return cam.aperture_diameter * cam.sensor_distance * abs(1 / near - 1 / far) / 2 / cam.sensor_pitch


def system_warnings(cam, task) -> list[str]:
    """What works but deserves the user's eye: bands or the design wavelength outside the range the
    substrate's published dispersion was fitted on (the index there is an extrapolation)."""
    from doefab.optics.materials import fit_range_warning

    notes = [fit_range_warning(cam.material, task.wavelengths(cam))]
    design = fit_range_warning(cam.material, [cam.design_wavelength])
    notes.append(f"design wavelength {design}" if design else None)
    notes.append(_design_wavelength_note(cam, task.wavelengths(cam)))
    notes.append(_diffraction_note(cam, task))
    notes.append(_far_focus_note(cam))
    notes.append(_staircase_note(cam, task))
    return [n for n in notes if n]


STAIRCASE_MAX = 0.01  # relative L2 of the coded PSF at the steepest plane (``staircase_error``) warned above


def _staircase_note(cam, task) -> str | None:
    """The coded half's PSF at the steepest plane off by more than ``STAIRCASE_MAX`` (``psf.staircase_error``: the
    DOE's pixels hold the point's wavefront flat), with the planes or pitch that bring it within (None otherwise)."""
    from doefab.optics.psf import staircase_error, staircase_step
    from doefab.pipeline.sampling import distance_text, phase_step_fix, steepest_plane

    lam_min = min(task.wavelengths(cam))
    z, step = steepest_plane(cam, lam_min, task.depths(cam))
    if staircase_error(step) <= STAIRCASE_MAX:
        return None
    fix = phase_step_fix(cam, lam_min, task.depths(cam), limit=staircase_step(STAIRCASE_MAX))
    return (f"a point at {distance_text(z)} changes its phase by {step:.2f} rad between DOE pixels at "
            f"{lam_min * 1e9:.0f} nm: the coded half's PSF there is about {staircase_error(step) * 100:.1f} % off "
            f"(relative L2, step² / (12 √3): each DOE pixel holds the wavefront flat), more than "
            f"{STAIRCASE_MAX * 100:g} %; for PSFs within it set {fix}")


def design_grid_notes(cam, task, factor: int) -> list[str]:
    """The design stage's coded PSF at the steepest plane off by more than ``STAIRCASE_MAX`` on the design grid
    (``design.sampling`` = ``factor``: a pupil ``factor``× coarser, so the wavefront's steps are ``factor``× larger)
    where the full grid's is within it, as a one-line note (none otherwise: a full grid above it has its own)."""
    from doefab.optics.psf import staircase_error, staircase_step
    from doefab.pipeline.sampling import design_camera, distance_text, phase_step_fix, steepest_plane

    if factor <= 1 or cam.doe_pixels % factor:
        return []
    lam_min, depths = min(task.wavelengths(cam)), task.depths(cam)
    full = staircase_error(steepest_plane(cam, lam_min, depths)[1])

    def error(d):
        return staircase_error(steepest_plane(design_camera(cam, d), lam_min, depths)[1])

    dcam = design_camera(cam, factor)
    z, step = steepest_plane(dcam, lam_min, depths)
    err = staircase_error(step)
    if full > STAIRCASE_MAX or err <= STAIRCASE_MAX:
        return []
    fits = max(d for d in range(1, factor) if cam.doe_pixels % d == 0 and error(d) <= STAIRCASE_MAX)
    other = phase_step_fix(dcam, lam_min, depths, factor, limit=staircase_step(STAIRCASE_MAX))
    return [f"design.sampling = {factor}: the design stage's pupil is {factor}× coarser, so a point at "
            f"{distance_text(z)} changes its phase by {step:.2f} rad between design pixels at {lam_min * 1e9:.0f} nm "
            f"and its coded PSF there is about {err * 100:.2g} % off (relative L2; the full grid's "
            f"{full * 100:.2g} %): the relief is optimised against PSFs the part will not have; for design PSFs "
            f"within {STAIRCASE_MAX * 100:g} % set design.sampling = {fits}{f', or {other}' if other else ''}"]


def _far_focus_note(cam) -> str | None:
    """A focus distance of 100 m or more where a point at infinity blurs by under half a pixel: the same focus as
    inf, and most often millimetres typed as metres (None otherwise)."""
    z = cam.focus_distance
    if math.isinf(z) or z < 100.0:
        return None
    blur = cam.defocus_blur_px(math.inf)
    if blur >= 0.5:
        return None
    return (f"camera.focus_distance_m = {z:g} m: a point at infinity blurs by {blur:.2g} px, "
            f"so this is the focus of inf; if you meant {z:g} mm, write focus_distance_m = {z / 1e3:g}")


def _diffraction_note(cam, task) -> str | None:
    """A diffraction blur wider than the task's metric (``Task.METRIC_WIDTH``): no relief concentrates light into
    a target narrower than the Airy core, 1.22 λ s / D at the longest band (None where it fits, within 1 px)."""
    if task.METRIC_WIDTH is None:
        return None
    attr, key = task.METRIC_WIDTH
    half, lam = float(getattr(task, attr)), max(task.wavelengths(cam))
    airy = 1.22 * lam * cam.sensor_distance / cam.aperture_diameter / cam.sensor_pitch
    if airy <= half + 1:
        return None
    return (f"the diffraction blur's Airy radius, {airy:.1f} px at {lam * 1e9:g} nm (1.22 λ s / D, along the split; "
            f"across it the half aperture's is twice that), is wider than the "
            f"{task.name} metric's ±{half:g} px ({key}): little of any PSF falls within it, so the design scores low; "
            f"set a lower camera.f_number, coarser camera.sensor_pitch_um or a wider {key}")


def _design_wavelength_note(cam, lams) -> str | None:
    """A design wavelength too short for the longest band or too long for the shortest: the relief's full depth, 2π
    there, delays a band λ by λ_d (n(λ) − 1) / (λ (n(λ_d) − 1)) waves; below ``MIN_WAVES`` at the longest (the
    paper's 550 nm design gives 700 nm 0.78) the relief reaches too little of that band's phase, above ``MAX_WAVES``
    at the shortest it wraps it several times (None otherwise)."""
    lam_d, lo, hi = cam.design_wavelength, min(lams), max(lams)
    n_d, n_hi = float(cam.material.index(lam_d)), float(cam.material.index(hi))
    waves = lam_d * (n_hi - 1) / (hi * (n_d - 1))
    most = lam_d * (float(cam.material.index(lo)) - 1) / (lo * (n_d - 1))
    if most > MAX_WAVES:
        return (f"fabrication.design_wavelength_nm {lam_d * 1e9:g} is long for the bands ({lo * 1e9:g}–{hi * 1e9:g} "
                f"nm): the relief's full depth, one wave at {lam_d * 1e9:g} nm, delays {lo * 1e9:g} nm by {most:.2f} "
                f"waves, so each etch level steps the short bands' phase by more than a wave's share and the etch is "
                f"deeper than the bands need; set it within the bands (nm)")
    if waves >= MIN_WAVES:
        return None
    return (f"fabrication.design_wavelength_nm {lam_d * 1e9:g} is short for the bands ({lo * 1e9:g}–{hi * 1e9:g} nm): "
            f"the relief's full depth, one wave at {lam_d * 1e9:g} nm, delays {hi * 1e9:g} nm by {waves:.2f} waves, "
            f"so the relief reaches little of that band's phase; set it nearer the longest band (at {hi * 1e9:g} "
            f"every band gets at least one wave)")


def sensor_warnings(scene: Scene, sensor, task, cam) -> list[str]:
    """A response an RGB task does not use; an RGB task's bands (its R, G and B channels) where the camera's
    default colour response does not see them (a near-infrared design: the colour scenes do not hold it)."""
    size = _sensor_size_note(scene, cam, task)
    out = [size] if size else []
    if has(scene.task, "spectral"):
        return out
    if "response" in scene.sensor and not sensor.has_default_response():
        out.append(f"sensor.response {scene.sensor['response']!r} is not used by the {scene.task} task: its scenes "
                   f"are the camera's own RGB (only the noise applies)")
    from doefab.imaging.sensor import bands_outside

    outside, words = bands_outside(task.wavelengths(cam))
    if outside.size:
        out.append(f"optics.wavelengths_nm: the {scene.task} task takes its bands as the camera's R, G and B "
                   f"channels, and {', '.join(f'{w * 1e9:.4g}' for w in outside)} nm lie outside {words}: its "
                   f"colour scenes hold no light there")
    return out


def _sensor_size_note(scene: Scene, cam, task) -> str | None:
    """A sensor (``camera.sensor_diagonal_mm``) whose diagonal, in its pixels, is shorter than the PSF window's or
    the test images': light a PSF spreads, or an image, that no sensor of that size records (None otherwise)."""
    d = scene.camera.get("sensor_diagonal_mm")
    if isinstance(d, bool) or not isinstance(d, (int, float)):
        return None
    across = d * 1e-3 / cam.sensor_pitch  # the sensor's diagonal in its pixels
    sides = {"the PSF window (optics.kernel_px)": task.kernel_size,
             "the test images (reconstruction.size_px)": int(scene.reconstruction.get("size_px", 256))}
    over = [f"{what}, {k} px, {k * math.sqrt(2):.0f} px across" for what, k in sides.items() if k * math.sqrt(2) > across]
    if not over:
        return None
    return (f"camera.sensor_diagonal_mm = {d:g}: the sensor is {across:.0f} px across its diagonal at "
            f"{cam.sensor_pitch * 1e6:g} µm, less than {' and '.join(over)}: no sensor of that size records them; "
            f"check the diagonal (in mm) and camera.sensor_pitch_um")


def calibration_notes(scene: Scene, sensor) -> list[str]:
    """The tolerance stage's crosstalk calibration where its noise swamps the sensor's own changes
    (``tolerance.errors.calibration_warning``: the scene's budget with the scene's sensor noise, as the stage
    judges); none without that stage."""
    if scene.tolerance is None or "tolerance" not in scene.stages:
        return []
    from doefab.tolerance.errors import calibration_warning, load_budget, with_sensor_noise

    note = calibration_warning(with_sensor_noise(load_budget(scene.budget_path()), sensor))
    return [note] if note else []


def depth_warnings(scene: Scene, cam, task, from_blur: bool) -> list[str]:
    """A depth design whose planes barely change the plain half's blur (no depth cue: often millimetres typed into
    a key in metres), and a default ring radius (the camera's defocus blur, ``defocus_ring_px``) capped to fit the
    PSF window. ``from_blur``: the ring was set from the blur (``system.ring_from_blur``)."""
    from doefab.tasks.halfring import HalfRingTask

    if not isinstance(task, HalfRingTask):
        return []
    near, far = min(task.depths(cam)), max(task.depths(cam))
    r, out = depth_span_px(cam, task.depths(cam)), []
    if r < 1:
        out.append(f"optics.depths_m {near:g}–{far:g} m: the plain half's blur changes by {r:.2g} px across the "
                   f"planes (D·s·|1/z_near − 1/z_far| / 2), so the captures carry almost no depth cue (depths are in "
                   f"metres)")
    if from_blur and r > task.ring_max_px + 1e-9:
        k = 2 * math.ceil(r + 2 + task.delta_px) + 1
        out.append(f"design.ring_max_px: the plain half's blur at the nearest plane when sharp at the farthest, "
                   f"{r:.1f} px, is capped to "
                   f"{task.ring_max_px:g} px, the most the {task.kernel_size} px window holds: the ring no longer "
                   f"follows the blur; set optics.kernel_px ≥ {k} to let it, or design.ring_max_px to choose")
    return out


def band_warnings(scene: Scene, cam, task) -> list[str]:
    """A grating's bands as a reconstruction stage's captures take them (each band one wavelength, its first order
    one spot): bands whose first orders lie more than 1.5 px apart leave a real spectrum's light between them out of
    the captures; bands closer than the scenes' measured 10 nm are interpolated between measured ones and carry
    nothing of their own."""
    from doefab.tasks.grating import GratingTask, grating_spot_px

    if not isinstance(task, GratingTask) or "reconstruction" not in scene.stages or len(
            lams := sorted(task.wavelengths(cam))) < 2:
        return []  # a design alone scores each band at its own wavelength: its captures are simulated for networks
    out = []
    spots = [grating_spot_px(cam, lam, task.period(cam)) for lam in lams]
    gap = max(abs(b - a) for a, b in zip(spots, spots[1:]))
    close = min(abs(b - a) for a, b in zip(spots, spots[1:]))
    if close < 1 / 1.5:
        out.append(f"optics.wavelengths_nm: adjacent bands' first orders lie {close:.2g} px apart, up to "
                   f"{1 / close:.1f} bands per sensor pixel: the coded capture cannot tell them apart; a shorter "
                   f"design.grating_period_um spreads them (doctor names the period that gives one per pixel)")
    if gap > 1.5:
        out.append(f"optics.wavelengths_nm: adjacent bands' first orders lie up to {gap:.1f} px apart, and the model "
                   f"takes each band as one wavelength: light between the bands (any real spectrum's) is not in the "
                   f"simulated captures; list bands about 1 px apart (here about "
                   f"{abs(spots[-1] - spots[0]) + 1:.0f} across the range) to model a continuous spectrum")
    step = min(b - a for a, b in zip(lams, lams[1:]))
    if step < DATA_STEP_M - 1e-12:
        out.append(f"optics.wavelengths_nm: bands {step * 1e9:.3g} nm apart, finer than the hyperspectral scenes' "
                   f"measured spectra ({DATA_STEP_M * 1e9:g} nm): the bands between measured ones are interpolated "
                   f"and carry no information of their own")
    return out
