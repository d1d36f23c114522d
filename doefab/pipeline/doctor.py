"""``doctor``: what a scene's numbers imply, and its numerical stiff spots, before hours are spent on them.

``explain``: the optical system in a reader's terms (f-number, diffraction limit and DOE pixels, depth of
field, the task's geometry in sensor pixels).

Every sampling condition the propagators check, with its margin (limit / value, ≥ 1 passes); the largest
phase step per pupil sample at the nearest depth; float32 against float64 on the stiffest PSF entry; the
spectral route's FFT memory; the condition of the crosstalk inverse; and whether the Wiener regularisation
of the shipped network keeps the deconvolution bounded. Each failing row says the fix.
"""

from __future__ import annotations

import math

import numpy as np

from doefab.applications import has
from doefab.pipeline.resolved import ResolvedScene
from doefab.validate import distance_or_inf

__all__ = ["diagnose", "explain"]


def _row(check, value, limit, unit, ok, fix="", at_least: bool = False):
    """``value`` must stay ≤ ``limit`` (or ≥ with ``at_least``); margin = how far inside (≥ 1 passes)."""
    if at_least:
        margin = value / limit if limit else math.inf
    else:
        margin = (limit / value) if value else math.inf
    return {"check": check, "value": value, "limit": limit, "bound": "≥" if at_least else "≤", "unit": unit,
            "margin": margin, "ok": bool(ok), "fix": "" if ok else fix}


# the run computes in float32 only; a scene that needs float64 computes its PSFs outside it
FLOAT64_FIX = ("the run computes in float32 only: compute this scene's PSFs with doefab psf --precision float64 "
               "(PSFPlan(precision='float64') in the API)")


def diagnose(scene, precision_check: bool = True, res: ResolvedScene | None = None) -> list[dict]:
    import torch

    from doefab.optics.psf import SOURCE_PHASE_LIMIT, PSFPlan
    from doefab.pipeline.stages import resolve
    from doefab.pipeline.sampling import distance_text, phase_step_fix, pitch_fix, steepest_plane

    res = res if res is not None else resolve(scene)  # the caller's, when it resolved the scene already
    cam = res.camera
    s = res.settings
    lams = s["wavelengths_m"]
    depths = [distance_or_inf(z) for z in s["depths_m"]]
    k = s["kernel_px"]
    rows = []
    lam_min = min(lams)
    alias_half = cam.alias_free_px(lam_min) * cam.sensor_pitch  # metres on the sensor
    half = (k / 2 + 0.5) * cam.sensor_pitch
    rows.append(_row("output window inside the alias-free field (shortest wavelength)", half, alias_half, "m",
                     half <= alias_half, " or ".join(
                         [f"optics.kernel_px ≤ {int(2 * alias_half / cam.sensor_pitch - 1)}"]
                         + pitch_fix(cam, lam_min * cam.sensor_distance / (2 * half)))))
    rows += _blur_row(cam, depths, k)
    z_near = min(depths)
    z, step = steepest_plane(cam, lam_min, depths)
    rows.append(_row(f"source phase step per pupil sample at the steepest plane's wavefront ({distance_text(z)})",
                     step, SOURCE_PHASE_LIMIT, "rad", step <= SOURCE_PHASE_LIMIT,
                     phase_step_fix(cam, lam_min, depths)))
    fft_bytes = spectral_fft_bytes(cam)
    rows.append(_row("spectral route FFT working memory (2× padded pupil, complex64, ~3 buffers)", fft_bytes,
                     FFT_BYTES_LIMIT, "bytes", fft_bytes <= FFT_BYTES_LIMIT,
                     "a coarser design grid (design.sampling) or fewer pixels"))
    if "tolerance" in scene.stages and scene.tolerance is not None:
        rows += tolerance_memory_rows(cam, s["n_levels"], len(lams), scene.tolerance)
        rows += _scheduler_rows(scene.tolerance.get("scheduler"))
    if precision_check:
        from doefab.fabrication.levels import levels_to_height

        height = None
        if res.reuse:
            from doefab.design.design import Design

            d = Design.load(res.committed_dir)
            height = levels_to_height(d.levels, d.camera)
        psf = {}
        for prec in ("float32", "float64"):
            plan = PSFPlan(cam, [lam_min], [z_near], k, halves=("coded",), precision=prec)
            with torch.no_grad():
                psf[prec] = plan(height).coded.double()
        diff = float((psf["float32"] - psf["float64"]).norm() / psf["float64"].norm())
        rows.append(_row("float32 against float64 PSF (shortest wavelength, nearest depth)", diff, 1e-3, "rel. L2",
                         diff <= 1e-3, FLOAT64_FIX))
    from doefab.imaging.sensorcrosstalk import SensorCrosstalk
    from doefab.tolerance.errors import load_budget, sensor_errors

    sens = sensor_errors(load_budget(scene.budget_path() if scene.tolerance is not None else None))
    # the sensor's worst pixel, as the tolerance study's captures are mixed (rising toward the region's corners;
    # the fixed row pattern of seed 0: each part's own moves it by up to about 0.003 at the shipped budget)
    det, a, b = SensorCrosstalk(sens["crosstalk"], sens["crosstalk_slope"],
                                width_px=sens["calibrated_width_px"]).worst_determinant()
    cond = float(np.linalg.cond(np.array([[1 - a, b], [a, 1 - b]])))
    rows.append(_row(f"crosstalk inverse determinant 1 − α_l→r − α_r→l at the sensor's worst pixel (α = {a:.3g}, "
                     f"{b:.3g}; matrix condition {cond:.2f})",
                     det, 0.05, "", det >= 0.05, "recalibrate the sensor: ratios this large leave the views unseparated",
                     at_least=True))
    try:
        from doefab.reconstruction.loader import load_reconstructor

        if not has(scene.task, "depth"):
            rec = load_reconstructor(scene.task, "proposed")
            lam_w = float(rec.model.coded.wiener.lam.detach().min())
            gain = 1 / (2 * math.sqrt(lam_w))
            rows.append(_row(f"Wiener deconvolution gain bound 1/(2√λ), λ_min = {lam_w:.3g} (shipped network)", gain,
                             1e3, "×", math.isfinite(gain) and gain <= 1e3, "retrain with a larger initial λ"))
        else:
            rows.append(_row("Wiener deconvolution: the depth network has none", 0.0, 1.0, "", True))
    except Exception as exc:  # noqa: BLE001 - no weights is a finding, not a crash
        rows.append(_row(f"Wiener regularisation: the shipped network cannot be checked ({str(exc)[:100]})", 1.0, 1.0,
                         "", False, f"doefab train --task {scene.task}"))
    return rows


#: the spectral route's FFT working memory a scene may ask for (bytes)
FFT_BYTES_LIMIT = 8e9


def spectral_fft_bytes(cam) -> int:
    """The spectral route's FFT working memory on ``cam``'s full grid (bytes): 2× padded pupil, complex64, ~3
    buffers."""
    return (2 * cam.doe_pixels) ** 2 * 8 * 3


def design_time_fact(res: ResolvedScene) -> dict:
    """The system fact of the design stage's run time on this machine (minutes): none where the committed design is
    reused, else measured by ``design.pace.design_time`` on the scene's own design (``stages.design_arguments``),
    unless its grid's FFTs exceed ``FFT_BYTES_LIMIT`` (a failing check says so)."""
    from doefab.pipeline.stages import design_arguments

    fact = {"quantity": "design stage's run time", "unit": "min"}
    if res.reuse:
        return {**fact, "value": 0.0, "meaning": "the committed design is reused: nothing is optimised"}
    args = design_arguments(res)
    if spectral_fft_bytes(res.camera) > FFT_BYTES_LIMIT:
        return {**fact, "value": float("nan"), "meaning": "not measured: the FFT memory check fails"}
    from doefab.design.pace import design_time

    t = design_time(**args)
    return {**fact, "value": t["seconds"] / 60, "meaning": (
        f"measured here ({t['device']}): {t['iterations']} {args['optimizer']} steps of {t['step_s']:.3g} s on the "
        f"{t['grid_px']}² grid, {t['evaluations']} full metrics of {t['metric_s']:.3g} s, set-up and the full-grid "
        f"finish; longer on a busier machine (doefab.design.pace)")}


def _blur_row(cam, depths, k: int) -> list[dict]:
    """The plain half's defocus blur (its half disc's radius) at its widest plane against the PSF window's reach,
    as ``resolve`` refuses it (``sampling.window_blur_checks``, which names the fixes); none where every plane is
    at the focus."""
    from doefab.optics.camera import window_reach
    from doefab.pipeline.sampling import distance_text

    z, r = cam.widest_blur(depths)
    return [_row(f"plain half's defocus blur inside the PSF window (its radius at {distance_text(z)})", r,
                 window_reach(k), "px", cam.window_holds_blur(depths, k), "optics.kernel_px")] if r > 0 else []


def tolerance_memory_rows(cam, n_levels: int, n_bands: int, tol: dict) -> list[dict]:
    """The memory the parts the tolerance stage judges at once take (one; ``tolerance.workers`` or a ``local:N``
    scheduler's N) on the grid the scene fixes (else the design grid, the coarsest the grid study can pick) against
    what this machine has available (``tolerance.fields.part_bytes``); none where that is unknown."""
    from doefab._memory import available_bytes
    from doefab.fabrication.process import mask_count
    from doefab.tolerance.fields import part_bytes
    from doefab.tolerance.grid import GRIDS, REFERENCE
    from doefab.tolerance.schedulers import parts_at_once

    have = available_bytes()
    if have is None:
        return []
    supersample = tol.get("supersample")
    parts = parts_at_once(tol.get("workers"), tol.get("scheduler"))
    s, m = int(supersample or 1), mask_count(n_levels)
    need = parts * part_bytes(cam.doe_pixels, s, m, n_bands)
    finer = "" if supersample else "; the grid study may pick a finer one: " + ", ".join(
        f"{g}× {parts * part_bytes(cam.doe_pixels, g, m, n_bands) / 1e9:.1f} GB" for g in (*GRIDS[1:], REFERENCE))
    what = f"{parts} judged parts' memory (one per worker)" if parts > 1 else "one judged part's memory"
    return [_row(f"tolerance: {what} on the {s}× grid, against this machine's available memory{finer}", need, have,
                 "bytes", need <= have, "a machine with more memory, fewer DOE pixels (a larger camera.doe_pitch_um)"
                 + (", or a coarser tolerance.supersample" if s > 1 else "")
                 + (", or fewer tolerance workers" if parts > 1 else ""))]


def _scheduler_rows(scheduler: str | None) -> list[dict]:
    """Whether the scene's ``tcp://`` Dask scheduler answers, as ``doefab run`` requires before any stage."""
    from doefab.errors import DoefabError
    from doefab.tolerance.schedulers import check_reachable, parse_scheduler

    if not scheduler or parse_scheduler(scheduler) is not None:
        return []
    try:
        check_reachable(scheduler, "tolerance.scheduler")
    except DoefabError as exc:
        return [_row(f"tolerance: the Dask scheduler {scheduler} answers", 0.0, 1.0, "", False, str(exc),
                     at_least=True)]
    return [_row(f"tolerance: the Dask scheduler {scheduler} answers", 1.0, 1.0, "", True, at_least=True)]


def explain(res: ResolvedScene, scene=None) -> list[dict]:
    """What a resolved scene's numbers imply: [{quantity, value, unit, meaning}] (thin lens; the DOE at the
    aperture; λ the middle of the task's bands); with the ``scene``, also the field its holder's hole passes and what
    the field's edge does to the etch step."""
    from doefab.optics.camera import STOP_TOLERANCE

    cam, task = res.camera, res.task
    lams = sorted(res.settings["wavelengths_m"])
    lam = lams[len(lams) // 2]
    f, d, s, p = cam.focal_length, cam.aperture_diameter, cam.sensor_distance, cam.sensor_pitch
    airy = 1.22 * lam * s / d / p
    coc = 2 * p  # a blur of two sensor pixels: the sharpness a capture keeps
    inv_f = 0.0 if math.isinf(cam.focus_distance) else 1 / cam.focus_distance
    near = 1 / (inv_f + coc / (d * s))
    far_inv = inv_f - coc / (d * s)
    far = math.inf if far_inv <= 0 else 1 / far_inv
    rows = [("focal length", f * 1e3, "mm", "thin lens focused at the focus distance"),
            ("f-number (DOE aperture)", f / d, "", f"{d * 1e3:.2f} mm clear aperture; each half passes half the light"),
            ("lens f-number", cam.lens_f_number, "", "the DOE's baffle is the aperture stop" if cam.doe_is_stop
             else f"the lens's pupil, up to {STOP_TOLERANCE * 100:g} % narrower than the baffle, is taken as the "
             "aperture stop: the DOE's diffraction over the gap is propagated"),
            ("diffraction limit (Airy radius)", airy, "sensor px", f"1.22 λ s / D at {lam * 1e9:.0f} nm; below 1 px "
             "the sensor, not diffraction, limits detail"),
            ("DOE pixels across the aperture", cam.doe_pixels, "px", _grid_text(cam, int(res.settings["sampling"]))),
            ("depth of field's near limit (2 px blur)", near, "m", f"far limit "
             f"{'∞' if math.isinf(far) else f'{far:.{_digits(near, far)}g} m: {far - near:.3g} m deep'} about the "
             f"focus at "
             + ("infinity (focused at the near limit, the hyperfocal distance, it would reach from half of it to ∞)"
                if inv_f == 0 else
                f"{cam.focus_distance:g} m"))]
    rows += (_task_rows(cam, task, lams) + _fab_rows(cam, res.settings["n_levels"])
             + _sensor_rows(res.sensor, res.settings["design_task"]) + _field_rows(scene, cam))
    return [{"quantity": q, "value": float(v), "unit": u, "meaning": m} for q, v, u, m in rows]


def _digits(near: float, far: float) -> int:
    """Significant digits that tell ``far`` from ``near`` (3 at least): a macro lens's depth of field of 0.3 mm at
    0.3 m needs 5 (0.30014 m, not 0.3 m)."""
    return max(3, 2 + math.ceil(-math.log10((far - near) / far))) if far > near > 0 else 3


def _field_rows(scene, cam) -> list[tuple]:
    """The field's half-angle the holder's hole in front of the DOE passes, and where it comes from (with a holder
    stage), and what the field's edge does to the DOE's phase (wherever the field is known)."""
    from doefab.pipeline.sceneholder import scene_field_half_angle_deg

    from holder_cad.params import HolderParams

    if scene is None:
        return []
    angle = scene_field_half_angle_deg(scene, cam)
    if "field_half_angle_deg" in scene.holder:
        why = "holder.field_half_angle_deg, as given"
    elif angle is not None:
        why = (f"atan(sensor diagonal / 2 / sensor distance) = atan({scene.camera['sensor_diagonal_mm']:g} / 2 / "
               f"{cam.sensor_distance * 1e3:.4g} mm)")
    elif "holder" in scene.stages:
        angle = HolderParams.field_half_angle_deg
        why = "the holder's default (a full-frame sensor at 50 mm): set camera.sensor_diagonal_mm for your sensor"
    else:
        return []
    rows = [("field the holder's hole passes (half-angle)", angle, "°", why)] if "holder" in scene.stages else []
    return rows + [_oblique_step_row(cam, angle)]


def _oblique_step_row(cam, angle_deg: float) -> tuple:
    """The phase of one etch step for a plane wave at the field's edge against on axis: k·h·(n·cos θt − cos θ),
    sin θ = n·sin θt (Snell), against k·h·(n − 1), at the design wavelength (``tilt_phase_factor``, the same
    obliquity as a tilted die's). The PSFs are computed on axis."""
    from doefab.tolerance.sources import tilt_phase_factor

    n = float(cam.material.index(cam.design_wavelength))
    change = (tilt_phase_factor(math.radians(angle_deg), n) - 1) * 100
    return ("etch step's phase at the field's edge", change, "%", f"k·h·(n cos θt − cos θ) against k·h·(n − 1) at "
            f"{angle_deg:.1f}°: the image's corners see the DOE as if etched {change:.1f} % deeper (the PSFs are "
            f"computed on axis; doefab tolerance --sweep shows what an etch-depth error costs)")


#: what a capture's clip means for the task of each design
CLIP_MEANS = {"streak": "the HDR task recovers highlights beyond its clip from the coded half's streaks",
              "grating": "pixels beyond its clip saturate; the spectral task does not recover them",
              "half-ring": "pixels beyond its clip saturate; the depth task does not recover them"}


def _sensor_rows(sensor, design_task: str) -> list[tuple]:
    """One capture's noise: shot-noise SNR at full scale and the range above the read-noise floor, and what its
    clip means for the task (``design_task``: streak, grating, half-ring)."""
    if sensor is None:
        return []
    fw, rn = sensor.full_well_e, sensor.read_noise_e
    rows = [("shot-noise SNR at full scale", math.sqrt(fw), "", f"√(full well) at {fw:g} e⁻; a pixel at 1 % of "
             f"full scale: {fw / 100 / math.sqrt(fw / 100 + rn ** 2):.3g}")]
    if rn > 0:
        rows.append(("capture dynamic range", math.log2(fw / rn), "stops", f"full well over read noise ({rn:g} e⁻ "
                     f"rms): one capture's range; {CLIP_MEANS[design_task]}"))
    return rows


def _fab_rows(cam, n_levels: int) -> list[tuple]:
    from doefab.fabrication.levels import level_step
    from doefab.fabrication.process import mask_count

    lam = cam.design_wavelength
    step = level_step(cam, n_levels)
    return [("substrate index", cam.material.index(lam), "", f"{cam.material.name} at the design wavelength "
             f"{lam * 1e9:.0f} nm"),
            ("etch depth of 2π", step * n_levels * 1e9, "nm", f"λ / (n − 1): {n_levels} levels of {step * 1e9:.1f} nm on "
             f"{mask_count(n_levels)} binary mask{'' if mask_count(n_levels) == 1 else 's'}")]


def _finer_grating(cam, task, lams, spots) -> str:
    """Where the grating spreads the bands over fewer pixels than there are bands (more than 1.5 bands per pixel):
    the period that spreads them one per pixel, in DOE pixels, and the window its farthest first order needs; or,
    where that window would leave the DOE sampling's alias-free field or the key's range, that no period does."""
    from doefab.pipeline.sampling import alias_free_px
    from doefab.pipeline.scenekeys import keys_of
    from doefab.tasks.grating import MAX_MAPPING_PX, grating_spot_px, period_for_mapping, period_for_spread

    n, lo, hi = len(lams), min(lams), max(lams)  # the scene's list in any order
    per_px = (n - 1) / max(abs(spots[1] - spots[0]), 1e-9)
    if n < 2 or per_px <= 1.5:
        return ""
    period = period_for_spread(cam, lo, hi, n - 1)
    if not math.isfinite(period):
        return ""
    period = math.floor(period * 1e6 * 100) / 100 * 1e-6  # down to 0.01 µm: at least one band per pixel
    far = grating_spot_px(cam, hi, period)
    kernel = task.window_px(far)
    here = f"; here {per_px:.1f} bands per pixel ({n} bands {(hi - lo) / (n - 1) * 1e9:.3g} nm apart): "
    field = alias_free_px(cam, lo)
    if kernel / 2 + 0.5 > field or kernel > keys_of("optics")["kernel_px"].hi:
        return (here + f"no grating period spreads them one per pixel on this DOE pitch ({period * 1e6:g} µm would "
                f"put the first order at {hi * 1e9:.0f} nm {far:.0f} px off axis, needing a {kernel} px window; "
                f"the alias-free field at {lo * 1e9:.0f} nm is {2 * field - 1:.0f} px): list fewer bands in "
                f"optics.wavelengths_nm, or a finer camera.doe_pitch_um")
    steep = period_for_mapping(cam, hi)
    if period < steep:  # the period that spreads them so far diffracts too steeply for the model
        return (here + f"no grating period spreads them one per pixel within the model ({period * 1e6:g} µm would; "
                f"below {steep * 1e6:g} µm the model puts the first order at {hi * 1e9:.0f} nm more than "
                f"{MAX_MAPPING_PX:g} px from the lens's): list fewer bands in optics.wavelengths_nm, or a longer "
                f"lens or finer sensor pixels")
    return (here + f"design.grating_period_um = {period * 1e6:g} spreads them one per pixel "
            f"({period / cam.doe_pitch:.1f} DOE pixels per period; its first order at {hi * 1e9:.0f} nm lands "
            f"{far:.0f} px off axis, within optics.kernel_px ≥ {kernel})")


def _grid_text(cam, sampling: int) -> str:
    """The DOE grid in words: its pitch and pixel count, and the design grid ``sampling`` coarsens it to."""
    n = cam.doe_pixels
    text = f"at {cam.doe_pitch * 1e6:g} µm, {n ** 2:,} pixels"
    if sampling > 1:
        text += (f"; the design optimises on {n // sampling}² px of {cam.doe_pitch * sampling * 1e6:g} µm "
                 f"(design.sampling {sampling}), upsampled to this grid when done")
    return text


def _task_rows(cam, task, lams) -> list[tuple]:
    from doefab.tasks.grating import GratingTask, grating_spot_px
    from doefab.tasks.halfring import HalfRingTask
    from doefab.tasks.streak import StreakTask

    if isinstance(task, GratingTask):
        spots = [grating_spot_px(cam, w, task.period(cam)) for w in (lams[0], lams[-1])]
        return [("grating dispersion across the band", abs(spots[1] - spots[0]), "sensor px",
                 f"first order from {abs(spots[0]):.1f} px ({lams[0] * 1e9:.0f} nm) to {abs(spots[1]):.1f} px "
                 f"({lams[-1] * 1e9:.0f} nm) off axis (s·λ/Λ, Λ = {task.period(cam) * 1e6:.3g} µm)"),
                ("spectral sampling", (lams[-1] - lams[0]) * 1e9 / max(abs(spots[1] - spots[0]), 1e-9), "nm/px",
                 "bands closer than this land on the same pixel" + _finer_grating(cam, task, lams, spots))]
    if isinstance(task, StreakTask):
        return [("streak arms", task.arm_px, "sensor px", f"each arm {task.arm_px} px long, "
                 f"{2 * task.band_px + 1} px wide: a highlight's light spread over them")]
    if isinstance(task, HalfRingTask):
        zs = task.depths(cam)
        r = [task.radius_px(z) for z in (min(zs), max(zs))]
        return [("half-ring radius", r[0], "sensor px", f"at the nearest plane ({min(zs):g} m), {r[1]:.1f} px at the "
                 f"farthest ({max(zs):g} m): {len(zs)} planes, ring law {task.ring_law}")]
    return []
