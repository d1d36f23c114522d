"""The optical system a scene describes: its camera, its task (bands, planes, geometry), its fabrication, and
whether that system is the one a committed design was made for (then that design, its masks and its networks
are reused).

A scene starts from a preset camera (the paper's prototype by default) and replaces whatever it sets: focal
length or sensor distance, DOE aperture or f-number, the lens's own f-number, focus, sensor and DOE pitch
(the DOE grid is the aperture divided by the DOE pitch, rounded up to an even number of pixels so the split
falls on a pixel edge), material and design wavelength. ``resolve`` then checks the physics before any work:
the fab must resolve the DOE pixel, the grid must stay within memory, the window must hold the task's light
(a grating's longest first order, a streak's arms, a half-ring's largest ring, the plain half's defocus blur
at every plane), the PSF window must sit inside the pupil sampling's alias-free field. Every problem is listed
with its key and its fix.
"""

from __future__ import annotations

import math

from doefab.errors import DoefabError, problems_error
from doefab.pipeline.sampling import (MAX_DOE_PIXELS, MIN_DOE_PIXELS, few_pixels_fixes, alias_free_px,
                                      design_camera, design_factor_checks, pitch_fix, design_grid_problems,
                                      distance_text, optimizer_checks, quick_sampling, sampling_checks,
                                      aperture_key, grid_fixes, stop_checks, window_blur_checks,
                                      grating_window_checks)
from doefab.applications import application, band_problem, design_is, has
from doefab.pipeline.designkeys import design_key_problems, design_key_warnings
from doefab.pipeline.resolved import ResolvedScene
from doefab.pipeline.scene import Scene, check_scene
from doefab.pipeline.systemnotes import (band_warnings, calibration_notes, depth_span_px, depth_warnings,
                                         design_grid_notes, sensor_warnings, system_warnings)
from doefab.pipeline.sceneholder import die_checks, holder_checks, holder_warnings, scene_die_m
from doefab.pipeline.scenekeys import weights_mode
from doefab.validate import distance_or_inf, distance_record

__all__ = ["resolve", "ResolvedScene", "scene_camera", "scene_task", "scene_sensor", "quick_sampling", "design_camera",
           "is_custom_camera", "system_warnings", "MAX_DOE_PIXELS", "shipped_sensor_differs"]


def is_custom_camera(scene: Scene, cam=None, fields: tuple | None = None) -> bool:
    """Whether the scene's camera (``cam``: it, already built) differs from its preset (a key equal to the
    preset's value changes nothing); ``fields``: only in these ``Camera.to_dict`` entries."""
    from doefab.optics.camera import Camera

    base = Camera.preset(scene.camera.get("preset", application(scene.task).camera_preset)).to_dict()
    cam = (cam if cam is not None else scene_camera(scene, [])).to_dict()  # its problems are resolve's to report
    return any(cam[f] != base[f] for f in (fields or cam))


def scene_camera(scene: Scene, problems: list | None = None):
    """The scene's Camera (SI units). A problem found building it is appended to ``problems`` (and a stand-in
    value used, so the other checks still run), or raised when no list is given."""
    from doefab.optics.camera import Camera
    from doefab.optics.materials import material_by_name

    def problem(text: str) -> None:
        if problems is None:
            raise DoefabError(text)
        problems.append(text)

    c, fab = scene.camera, scene.fabrication
    base = Camera.preset(c.get("preset", application(scene.task).camera_preset))
    focus = distance_or_inf(c.get("focus_distance_m", base.focus_distance))
    inv_focus = 0.0 if math.isinf(focus) else 1.0 / focus
    if "sensor_distance_mm" in c or "sensor_distance_m" in c:
        s = c["sensor_distance_mm"] * 1e-3 if "sensor_distance_mm" in c else float(c["sensor_distance_m"])
    elif "focal_length_mm" in c:
        f = c["focal_length_mm"] * 1e-3
        if f * inv_focus >= 1:
            problem(f"camera.focal_length_mm {c['focal_length_mm']} cannot focus at {focus} m: the focus distance "
                    f"must exceed the focal length")
            inv_focus, focus = 0.0, math.inf  # stand-in: focused at infinity, so the other checks still run
        s = 1.0 / (1.0 / f - inv_focus)
    else:
        s = base.sensor_distance
    focal = 1.0 / (1.0 / s + inv_focus)
    aperture = (c["aperture_diameter_mm"] * 1e-3 if "aperture_diameter_mm" in c
                else focal / c["f_number"] if "f_number" in c else base.aperture_diameter)
    pitch = c["doe_pitch_um"] * 1e-6 if "doe_pitch_um" in c else base.doe_pitch
    changed = any(k in c for k in ("aperture_diameter_mm", "f_number", "doe_pitch_um"))
    pixels = 2 * math.ceil(aperture / pitch / 2 - 1e-9) if changed else base.doe_pixels
    if pixels > MAX_DOE_PIXELS:
        problem(f"the DOE grid would be {pixels}² pixels ({aperture * 1e3:.2f} mm / {pitch * 1e6:g} µm): above "
                f"{MAX_DOE_PIXELS}²; set {grid_fixes(aperture, pitch, focal, aperture_key(c))}")
        pixels, pitch = MAX_DOE_PIXELS, aperture / MAX_DOE_PIXELS  # stand-in grid for the other checks
    elif pixels < MIN_DOE_PIXELS:
        problem(f"the DOE grid would be {pixels} pixels across ({aperture * 1e3:.3g} mm / {pitch * 1e6:g} µm): "
                f"below the {MIN_DOE_PIXELS} a pattern needs; set "
                f"{few_pixels_fixes(aperture, pitch, focal, aperture_key(c))}")
        pixels, pitch = MIN_DOE_PIXELS, aperture / MIN_DOE_PIXELS  # stand-in grid for the other checks
    try:
        material = material_by_name(fab["material"]) if "material" in fab else base.material
    except DoefabError as exc:
        problem(f"fabrication.material: {exc}")
        material = base.material
    try:
        return base.replace(sensor_distance=s, focus_distance=focus, aperture_diameter=aperture, doe_pitch=pitch,
                            doe_pixels=int(pixels),
                            sensor_pitch=c["sensor_pitch_um"] * 1e-6 if "sensor_pitch_um" in c else base.sensor_pitch,
                            lens_f_number=float(c.get("lens_f_number", base.lens_f_number)), material=material,
                            design_wavelength=fab["design_wavelength_nm"] * 1e-9 if "design_wavelength_nm" in fab
                            else base.design_wavelength)
    except DoefabError as exc:  # the camera's own checks (e.g. a DOE grid smaller than the aperture)
        problem(f"camera: {exc}")
        return base


def scene_sensor(scene: Scene, problems: list | None = None):
    """The scene's ``imaging.sensor.Sensor`` (its ``[sensor]`` section over the default camera's). A problem (an
    unreadable CSV) is appended to ``problems`` and the default sensor returned, or raised without a list."""
    from doefab.imaging.sensor import Sensor, noise_fields

    try:
        return Sensor(response=scene.response_path(), **noise_fields(scene.sensor))
    except DoefabError as exc:
        if problems is None:
            raise
        problems.append(f"sensor: {exc}")
        return Sensor()


def _sensor_checks(scene: Scene, sensor, task, cam) -> list[str]:
    """The response must cover a spectral task's bands where a reconstruction stage is asked for (a design and its
    masks take the bands alone)."""
    if not has(scene.task, "spectral") or "reconstruction" not in scene.stages:
        return []
    try:
        sensor.rgb(task.wavelengths(cam))
    except DoefabError as exc:
        return [f"sensor.response / optics.wavelengths_nm: {exc}"]  # the response's message carries the fix
    return []


def scene_task(scene: Scene, committed, cam):
    """The scene's task: the committed design's parameters, replaced by the scene's bands, planes and geometry."""
    from doefab.tasks import get_task

    dname = application(scene.task).design_task
    params = {k: v for k, v in committed.task_params.items() if k != "period_m"}
    own = get_task(dname, **params)
    o, d = scene.optics, scene.design
    if "kernel_px" in o:
        params["kernel_size"] = int(o["kernel_px"])
    if "wavelengths_nm" in o and [round(w, 6) for w in o["wavelengths_nm"]] != [
            round(w * 1e9, 6) for w in own.wavelengths(cam)]:
        params["wavelengths_m"] = tuple(w * 1e-9 for w in o["wavelengths_nm"])
        if design_is(dname, "spectral"):
            params["n_bands"] = len(o["wavelengths_nm"])
    planes = [distance_or_inf(z) for z in o.get("depths_m", [])]
    if inside := [z for z in planes if z <= cam.focal_length]:
        verb = "lies" if len(inside) == 1 else "lie"
        raise DoefabError(f"optics.depths_m: {', '.join(f'{z:g}' for z in inside)} m {verb} within the lens's focal "
                          f"length "
                          f"({cam.focal_length * 1e3:.3g} mm), where a point forms no real image: set every plane "
                          f"farther away (the depths are in metres)")
    if design_is(dname, "depth") and any(math.isinf(z) for z in planes):
        raise DoefabError(f"optics.depths_m {o['depths_m']}: a depth design's planes are finite distances (its ring "
                          f"law needs 1/z at every plane): drop the plane at infinity")
    if planes and design_is(dname, "depth") and [round(z, 9) for z in planes] != [round(z, 9) for z in own.depths(cam)]:
        params["planes_m"] = tuple(planes)
    for key, name, scale in (("streak_arm_px", "arm_px", 1), ("streak_band_px", "band_px", 1),
                             ("grating_box_px", "box_px", 1), ("ring_max_px", "ring_max_px", 1),
                             ("ring_width_px", "delta_px", 1),
                             ("ring_law", "ring_law", None)):
        if key in d:
            params[name] = d[key] if scale is None else d[key] * scale
    if "grating_period_um" in d:
        params["period_m"] = d["grating_period_um"] * 1e-6
    if design_is(dname, "depth") and ring_from_blur(scene, cam, params.get("planes_m") or own.depths(cam)):
        params["ring_max_px"] = defocus_ring_px(cam, params)
    try:
        task = get_task(dname, **params)
        task.bind(cam)
    except DoefabError as exc:
        raise DoefabError(f"the task's keys (optics.wavelengths_nm, optics.depths_m, optics.kernel_px, [design] "
                          f"geometry): {exc}") from None
    return task


PAPER_RING_FAR_M = 5.0  # the paper's ring law, 25 − 5·z px, draws no ring at or beyond 5 m


def ring_from_blur(scene: Scene, cam, planes) -> bool:
    """Whether a depth scene's ring at the nearest plane is the camera's defocus blur (``defocus_ring_px``): no
    ``design.ring_max_px`` and a camera of its own, or planes (metres) from ``PAPER_RING_FAR_M`` on, where the
    paper's law for its prototype would leave every ring a point."""
    return "ring_max_px" not in scene.design and (is_custom_camera(scene, cam, BLUR_FIELDS)
                                                  or min(planes) >= PAPER_RING_FAR_M)


# what sets the plain half's defocus blur (D·s·|1/z_focus − 1/z| / 2, in sensor pixels): the substrate, the design
# wavelength and the lens's own f-number do not
BLUR_FIELDS = ("aperture_diameter_m", "sensor_distance_m", "focus_distance_m", "sensor_pitch_m")


def _camera_variant(scene: Scene, keys: dict):
    """The camera the scene builds with ``keys`` of its camera table changed, or None where it refuses them."""
    import dataclasses

    try:
        return scene_camera(dataclasses.replace(scene, camera={**scene.camera, **keys}))
    except DoefabError:
        return None


def defocus_ring_px(cam, params: dict) -> float:
    """The radius a defocus-law ring needs at the nearest plane (``depth_span_px``), capped to the window."""
    r = depth_span_px(cam, params.get("planes_m") or (params.get("z_min", 1.0), params.get("z_max", 5.0)))
    # within the window with the ring's half-width and 1 px (``HalfRingTask.pattern_reach_px``)
    return float(max(min(r, params.get("kernel_size", 63) // 2 - 2 - params.get("delta_px", 1.0)), 0.0))


def _checks(scene: Scene, cam, task) -> list[str]:
    """Physics guards: each problem with its key and fix."""
    from doefab.fabrication.process import check_min_feature
    from doefab.tasks.grating import GratingTask
    from doefab.tasks.halfring import HalfRingTask
    from doefab.tasks.streak import StreakTask

    out = []
    k = task.kernel_size
    if "min_feature_um" in scene.fabrication:
        try:
            pitch = scene.camera["doe_pitch_um"] * 1e-6 if "doe_pitch_um" in scene.camera else cam.doe_pitch
            check_min_feature(pitch, scene.fabrication["min_feature_um"] * 1e-6)
        except DoefabError as exc:
            out.append(f"camera.doe_pitch_um / fabrication.min_feature_um: {exc}")
    lam_min = min(task.wavelengths(cam))
    alias = alias_free_px(cam, lam_min)
    if k / 2 + 0.5 > alias:
        fixes = [f"optics.kernel_px ≤ {max(1, int(2 * alias - 1))}"] + pitch_fix(cam, cam.doe_pitch * alias /
                                                                                (k / 2 + 0.5))
        out.append(f"optics.kernel_px {k} reaches beyond the DOE sampling's alias-free field ({2 * alias - 1:.0f} px "
                   f"at {lam_min * 1e9:.0f} nm): set {' or '.join(fixes)}")
    if isinstance(task, GratingTask):
        out += grating_window_checks(cam, task)
    elif task.fits_window(cam):
        pass  # the pattern fits its window (``Task.window_problem``, which ``optimize`` refuses by)
    elif isinstance(task, StreakTask):
        out.append(f"design.streak_arm_px {task.arm_px} does not fit optics.kernel_px {k}: raise kernel_px to ≥ "
                   f"{task.window_for_pattern(cam)}")
    elif isinstance(task, HalfRingTask):
        r = max(task.radius_px(z) for z in task.depths(cam))
        out.append(f"the half-ring's largest ring ({r:.0f} px, {task.delta_px:g} px wide each side) does not fit "
                   f"optics.kernel_px {k}: raise kernel_px to ≥ {task.window_for_pattern(cam)}, "
                   f"or lower design.ring_max_px or design.ring_width_px")
    else:  # a task of another application
        out.append(f"optics.kernel_px {k}: {task.window_problem(cam)}")
    if isinstance(task, HalfRingTask) and len(flat := [z for z in task.depths(cam) if task.radius_px(z) <= 1e-9]) > 1:
        out.append(f"the half-ring's radius is 0 px at {len(flat)} planes ({', '.join(f'{z:g}' for z in flat)} "
                   f"m): its PSF cannot tell them apart; set design.ring_max_px (the half aperture's blur at the "
                   f"nearest plane is {depth_span_px(cam, task.depths(cam)):.1f} px) or design.ring_law = "
                   f"\"defocus\", or keep the planes nearer")
    planes = [distance_or_inf(z) for z in scene.optics.get("depths_m", [])]
    if planes and not isinstance(task, HalfRingTask) and [round(z, 9) for z in planes] != [
            round(z, 9) for z in task.depths(cam)]:
        out.append(f"optics.depths_m {scene.optics['depths_m']}: the {scene.task} design works at one plane, the "
                   f"focus distance, {distance_text(cam.focus_distance)}: set camera.focus_distance_m or drop depths_m")
    networks = "reconstruction" in scene.stages and weights_mode(scene.reconstruction.get("weights")).any_system
    if networks and (bands := band_problem(scene.task, task.wavelengths(cam))):  # else skipped on another design
        out.append(f"optics.wavelengths_nm: {bands}; or leave \"reconstruction\" out of stages to design for these "
                   f"bands alone")
    mode = weights_mode(scene.reconstruction.get("weights"))
    if networks and mode.any_system and not mode.trains and not bands:  # (bands: the problem above says it)
        from doefab.reconstruction.loader import shipped_fit_problem

        try:
            fit = shipped_fit_problem(scene.task, task.wavelengths(cam), task.depths(cam))
        except DoefabError as exc:  # the shipped weights themselves unreadable: one more problem in the list
            fit = str(exc)
        if fit:
            out.append(f"reconstruction.weights = \"{mode.name}\": {fit}: set reconstruction.weights = \"train\" "
                       f"to train networks for this design, or leave \"reconstruction\" out of stages")
    if "reconstruction" in scene.stages and has(scene.task, "spectral") and not all(
            400e-9 - 1e-12 <= w <= 700e-9 + 1e-12 for w in task.wavelengths(cam)):
        out.append("optics.wavelengths_nm: the hyperspectral scenes' reflectances and lights are known on 400–700 nm;"
                   " keep the bands within it, or leave \"reconstruction\" out of stages to design for these bands "
                   "alone")
    return out


def shipped_sensor_differs(task: str, sensor) -> list[str]:
    """What of ``sensor`` (None: the default) the shipped ``task`` networks were not trained for (empty: nothing)."""
    if sensor is None:
        return []
    from doefab.io import read_json
    from doefab.reconstruction.weights import weights_paths

    try:
        meta = read_json(weights_paths(task, "proposed")[1])
    except (OSError, ValueError):
        meta = {}
    return sensor.differs_from(meta.get("sensor") if isinstance(meta, dict) else None,
                               spectral=has(task, "spectral"))


def _skipped_networks(scene: Scene, cam, task, differ: list, sensor) -> list[str]:
    """A warning where the reconstruction stage will be skipped: the shipped networks (``reconstruction.weights``
    "shipped") on a design that differs from the committed one in ``differ``, or for another sensor; naming the
    choice that doctor would pass."""
    other = shipped_sensor_differs(scene.task, sensor)
    if ((not differ and not other) or "reconstruction" not in scene.stages
            or weights_mode(scene.reconstruction.get("weights")).any_system):
        return []
    why = (f"this scene's design differs ({', '.join(differ)})" if differ else "") + (" and " if differ and other
                                                                                       else "")
    why += f"its sensor differs ({'; '.join(other)})" if other else ""
    head = (f"reconstruction: the shipped networks are trained for the committed design and the default sensor, and "
            f"{why}, so the reconstruction stage will be skipped")
    if bands := band_problem(scene.task, task.wavelengths(cam)):
        return [f"{head}; no network takes these bands ({bands}): leave \"reconstruction\" out of stages"]
    from doefab.reconstruction.loader import shipped_fit_problem

    try:
        fits = not shipped_fit_problem(scene.task, task.wavelengths(cam), task.depths(cam))
    except DoefabError:
        fits = False
    anyway = " (or \"shipped-anyway\" to evaluate the shipped ones on its captures)" if fits else ""
    return [f"{head}: set reconstruction.weights = \"train\" to train networks for it{anyway}"]


def _settings(dname, cam, task, design: dict, cfg: dict, committed, fab: dict) -> dict:
    lams, depths = tuple(task.wavelengths(cam)), tuple(task.depths(cam))
    s = {"design_task": dname, "camera": cam.to_dict(), "wavelengths_m": list(lams),
         "depths_m": [distance_record(z) for z in depths], "kernel_px": task.kernel_size,
         "task_params": {k: v for k, v in task.params().items() if k not in ("period_m", "wavelengths_m", "planes_m")},
         "optimizer": design.get("optimizer", cfg.get("optimizer", "adam")),
         "iterations": design.get("iterations", cfg.get("iterations", task.default_iterations)),
         "sampling": design.get("sampling", cfg.get("sampling", 1)), "seed": design.get("seed", cfg.get("seed", 0)),
         "parameterization": design.get("parameterization", cfg.get("parameterization", "pixel")),
         "knots": design.get("knots", cfg.get("knots", 0)),
         "n_levels": int(fab.get("n_levels", committed.n_levels))}
    if design_is(dname, "depth"):
        s["ring_law"] = task.ring_law
    if design_is(dname, "spectral"):  # the period in metres (task_params hold it only as the preset's pixel count)
        s["grating_period_m"] = round(task.period(cam), 12)
    return s


def resolve(scene: Scene) -> ResolvedScene:
    """The scene's system (``ResolvedScene``: its camera, built once, its task, the design settings it asks for
    and whether they equal the committed design's), after every physics problem of it is checked (one DoefabError
    listing them all, before any work)."""
    from doefab.design.committed import committed_dir
    from doefab.design.design import Design

    check_scene(scene)  # a Scene built in code, as a file would be
    dname = application(scene.task).design_task
    cdir = committed_dir(dname)
    committed = Design.load(cdir)
    cfg = committed.extra.get("config", {})
    problems: list[str] = []
    cam = scene_camera(scene, problems)
    sensor = scene_sensor(scene, problems)
    if not any(p.startswith("camera: ") for p in problems):  # no camera at all: nothing else can be checked
        try:
            task = scene_task(scene, committed, cam)
        except DoefabError as exc:
            problems.append(str(exc))
        else:
            factor = int(scene.design.get("sampling", cfg.get("sampling", 1)))
            aperture = aperture_key(scene.camera)
            problems += (_checks(scene, cam, task) + _sensor_checks(scene, sensor, task, cam)
                         + window_blur_checks(cam, task, lambda **keys: _camera_variant(scene, keys), aperture)
                         + stop_checks(cam, aperture)
                         + sampling_checks(scene, cam, cfg) + optimizer_checks(scene, cam, cfg, task)
                         + design_factor_checks(scene, cam, task, factor, cfg)
                         + holder_checks(scene, cam) + die_checks(scene, cam) + design_key_problems(scene, cfg))
    if problems:
        raise problems_error(scene.path, problems)
    settings = _settings(dname, cam, task, scene.design, cfg, committed, scene.fabrication)
    ctask = scene_task(Scene(path=scene.path, task=scene.task, stages=()), committed, committed.camera)
    committed_settings = _settings(dname, committed.camera, ctask, {}, cfg, committed, {})
    differ = sorted(k for k in settings if settings[k] != committed_settings.get(k))
    skipped = _skipped_networks(scene, cam, task, differ, sensor)  # stage_reconstruction's skip, said before
    if "tolerance" in scene.stages and scene.tolerance is None and "stages" in scene.raw:  # listed, yet skipped
        skipped.append("tolerance: the scene has no [tolerance] table, so the tolerance stage will be skipped: add "
                       "one (e.g. [tolerance] with samples = 20; budget = \"default\" is the shipped budget) to "
                       "judge its parts, or leave \"tolerance\" out of stages")
    return ResolvedScene(
        settings=settings, camera=cam, task=task, committed_dir=cdir, committed=committed,
        committed_settings=committed_settings, reuse=not differ, differ=tuple(differ),
        custom_camera=is_custom_camera(scene, cam), split=scene.camera.get("split", "vertical"), stop=_stop(cam),
        sensor=sensor, die_m=scene_die_m(scene, cam),
        quick_sampling=quick_sampling(cam.doe_pixels, int(settings["sampling"]),
                                      lambda d: not design_grid_problems(cam, task, d)),
        warnings=tuple(system_warnings(cam, task) + sensor_warnings(scene, sensor, task, cam)
                       + design_grid_notes(cam, task, int(settings["sampling"]))
                       + depth_warnings(scene, cam, task, ring_from_blur(scene, cam, task.depths(cam)))
                       + band_warnings(scene, cam, task) + skipped + holder_warnings(scene, cam)
                       + design_key_warnings(scene, cfg, task) + calibration_notes(scene, sensor)),
        stage_warnings=tuple(skipped))


def _stop(cam) -> str:
    from doefab.tolerance.mounted import stop_case

    return stop_case(cam)
