"""The design grid's sampling: what the PSF routes accept on the full DOE grid and on the coarser grid the design
stage optimises on (``design.sampling``, ``--quick``'s factor), and the scene keys that fix what they refuse.

``resolve`` runs these checks before any work, so ``doefab doctor`` refuses exactly the scenes the design stage
would stop on: a sampling that does not divide the grid, a plane (the nearest, or one far beyond the focus) whose
point source changes its phase too fast between (design) pixels (``steepest_plane``), a window beyond the design
grid's alias-free field, a window too small for the plain half's defocus blur at a plane (``window_blur_checks``)
or for a grating's first orders (``grating_window_checks``), a lens whose entrance pupil cuts the DOE's baffle
(``stop_checks``).
``quick_sampling`` picks the ``--quick`` coarsening among the factors that pass.
"""

from __future__ import annotations

import math

from doefab.optics.camera import BLUR_ROOM_PX, window_reach
from doefab.pipeline.scene import Scene

__all__ = ["MAX_DOE_PIXELS", "MIN_DOE_PIXELS", "few_pixels_fixes",
           "source_phase_step", "steepest_plane", "pitch_fix", "phase_step_fix", "quick_sampling",
           "design_camera", "design_grid_problems", "design_factor_checks", "sampling_checks", "optimizer_checks",
           "nlopt_takes", "alias_free_px", "window_blur_checks", "grating_window_checks", "stop_checks",
           "distance_text", "grid_fixes", "aperture_key"]

MAX_DOE_PIXELS = 8192  # a larger grid's PSFs do not fit this machine's memory in reasonable time
MIN_DOE_PIXELS = 16  # a DOE fewer pixels across holds no pattern worth designing (nor a design grid coarsened)


def alias_free_px(cam, lam: float) -> float:
    """Half-width of the alias-free field the DOE's sampling leaves at wavelength ``lam`` (metres), in sensor
    pixels (``Camera.alias_free_px``); a window of k px fits where k/2 + 0.5 does not exceed it."""
    return cam.alias_free_px(lam)


def window_blur_checks(cam, task, variant=None, aperture_key: str = "f_number") -> list[str]:
    """The PSF window must hold the plain half's defocus blur (its geometric half disc) at every plane: the light
    beyond the window is missing from the simulated captures. The fixes, each leaving ``BLUR_ROOM_PX`` of room: a
    wider window (where the alias-free field and the key's range allow), and with ``variant`` (the camera the
    scene builds with some of its camera keys changed, None where it refuses them) a focus between the planes
    and a smaller aperture (``aperture_key``: the scene's own, ``f_number`` or ``aperture_diameter_mm``), each
    checked on the camera it gives."""
    k = task.kernel_size
    depths = task.depths(cam)
    if cam.window_holds_blur(depths, k):
        return []
    z, r = cam.widest_blur(depths)
    fixes = []
    need = cam.window_for_blur(depths)
    alias = alias_free_px(cam, min(task.wavelengths(cam)))
    if need <= 1023 and need / 2 + 0.5 <= alias:
        fixes.append(f"optics.kernel_px ≥ {need}")
    if variant is not None:
        fixes += _camera_fixes(cam, depths, r, window_reach(k) - BLUR_ROOM_PX, variant, aperture_key)
    return [f"optics.kernel_px {k}: the plain half blurs a point at {distance_text(z)} into a half disc of {r:.1f} px "
            f"radius (D·s·|1/z_focus − 1/z| / 2, focused at {distance_text(cam.focus_distance)}), and the PSF window "
            f"reaches {window_reach(k)} px from the point's image: the light beyond it would be missing from the "
            f"simulated captures; "
            + ("set " + " or ".join(fixes) if fixes else "no window in the alias-free field, focus or f-number in its "
               "key's range holds it: bring optics.depths_m closer together")]


def grating_window_checks(cam, task) -> list[str]:
    """A grating's first order of every band must land in the PSF window with its metric box and 2 px (the design's
    target and metric sit there; a period without a first order is refused before, by ``GratingTask.bind``, and a
    period not shorter than the coded half, where no first order separates from the zeroth, here first). The
    fixes: the window that holds it, and the shortest ``design.grating_period_um`` that brings it inside the
    window the scene has (``tasks.grating.period_for_reach``), where that period is within the key's range and the
    bands stay at most 1.5 per sensor pixel apart (``doctor``'s spectral sampling note)."""
    from doefab.pipeline.scenekeys import keys_of
    from doefab.tasks.grating import grating_spot_px, period_for_reach

    k, lams = task.kernel_size, task.wavelengths(cam)
    half = cam.aperture_diameter / 2  # the coded half's width across the split
    if task.period(cam) >= half:
        fit = min(16 * cam.doe_pitch, half / 4)  # several periods across the half
        return [f"the grating period {task.period(cam) * 1e6:g} µm (design.grating_period_um) is not shorter than "
                f"the coded half ({half * 1e6:g} µm across): less than one period fits, so no first order separates "
                f"from the zeroth; set design.grating_period_um shorter, e.g. {fit * 1e6:.3g}"]
    if task.fits_window(cam):
        return []
    longer = period_for_reach(cam, max(lams), k // 2 - task.box_px - 2)
    ok = math.isfinite(longer) and longer * 1e6 <= keys_of("design")["grating_period_um"].hi
    if ok and len(lams) > 1:
        spread = grating_spot_px(cam, max(lams), longer) - grating_spot_px(cam, min(lams), longer)
        ok = (len(lams) - 1) / spread <= 1.5
    period = f", or keep it and set design.grating_period_um ≥ {longer * 1e6:g} (µm)" if ok else ""
    return [f"optics.kernel_px {k}: the grating's first order lands {task.first_order_px(cam):.0f} px off axis: "
            f"raise kernel_px to ≥ {task.window_for_pattern(cam)}{period}"]


def distance_text(z: float) -> str:
    """A distance in words: ``"2 m"``, or ``"infinity"``."""
    return f"{z:g} m" if math.isfinite(z) else "infinity"


def _camera_fixes(cam, depths, r: float, reach: float, variant, aperture_key: str) -> list[str]:
    """The focus between the planes (the harmonic middle of the nearest and farthest) and the aperture that bring
    the blur's radius ``r`` within ``reach`` px, where the scene's camera keys' ranges allow them and the camera
    they give (its sensor distance moves with the focus when the scene fixes the focal length) holds the blur."""
    from doefab.pipeline.scenekeys import keys_of

    keys = keys_of("camera")

    def fits(name: str, value: float) -> bool:
        new = variant(**{name: value}) if keys[name].lo <= value <= keys[name].hi else None
        return new is not None and new.window_holds_blur(depths, 2 * reach + 1) and not new.lens_cuts_doe

    out = []
    inv = [0.0 if math.isinf(d) else 1 / d for d in depths]
    mid = (max(inv) + min(inv)) / 2
    if mid > 0 and fits("focus_distance_m", float(f"{1 / mid:.3g}")):
        out.append(f"camera.focus_distance_m = {1 / mid:.3g} (between the planes)")
    scale = reach / r  # the blur's radius is proportional to the aperture
    if aperture_key == "aperture_diameter_mm":
        d = _round3(cam.aperture_diameter * 1e3 * scale, math.floor)
        if fits("aperture_diameter_mm", d):
            out.append(f"camera.aperture_diameter_mm ≤ {d:g}")
    else:
        n = _round3(cam.focal_length / (cam.aperture_diameter * scale), math.ceil)
        if fits("f_number", n):
            out.append(f"camera.f_number ≥ {n:g}")
    return out


def stop_checks(cam, aperture_key: str = "f_number") -> list[str]:
    """The DOE's baffle must be the aperture stop, or about as wide as the lens's entrance pupil
    (``Camera.lens_cuts_doe``): the PSFs carry the light of the whole baffle, split at the DOE, and a narrower lens
    pupil would block the baffle's outer ring. The fix makes the baffle no wider than the pupil (``aperture_key``:
    the scene's own, ``f_number`` or ``aperture_diameter_mm``; an f-number where the pupil is narrower than the
    aperture key's range)."""
    from doefab.pipeline.scenekeys import keys_of

    if not cam.lens_cuts_doe:
        return []
    pupil, doe = cam.lens_pupil_diameter * 1e3, cam.aperture_diameter * 1e3
    low, widest = keys_of("camera")["aperture_diameter_mm"].lo, _round3(pupil, math.floor)
    if aperture_key == "aperture_diameter_mm" and widest >= low:
        fix = f"camera.aperture_diameter_mm ≤ {widest:g}"
    else:  # the f-number the lens has fits its key's range; an aperture below the range's end does not
        fix = f"camera.f_number ≥ {_round3(cam.lens_f_number, math.ceil):g}" + (
            f" (in place of camera.aperture_diameter_mm, whose range ends at {low:g} mm)"
            if aperture_key == "aperture_diameter_mm" else "")
    return [f"camera.lens_f_number {cam.lens_f_number:g}: the lens's {pupil:.2f} mm entrance pupil is narrower than "
            f"the DOE's {doe:.2f} mm baffle, so the lens would block the DOE's outer ring, which the PSFs (computed "
            f"over the whole baffle) carry: make the DOE the aperture stop with {fix}, or set camera.lens_f_number to "
            f"the lens's own wide-open f-number if it opens wider"]


def aperture_key(camera_keys: dict) -> str:
    """The key a scene's ``[camera]`` section sets its DOE aperture with: ``aperture_diameter_mm`` where given,
    else ``f_number`` (what the fixes of the stop, blur and grid checks name)."""
    return "aperture_diameter_mm" if "aperture_diameter_mm" in camera_keys else "f_number"


def grid_fixes(aperture: float, pitch: float, focal: float, aperture_key: str = "f_number") -> str:
    """What brings a DOE grid of ``aperture`` / ``pitch`` pixels (m, m) within ``MAX_DOE_PIXELS``: a coarser pitch,
    or a smaller aperture in the scene's own key (``aperture_key``: ``f_number``, with ``focal`` the focal length
    in m, or ``aperture_diameter_mm``), each rounded to three digits on the side that fits.

    Example: ``grid_fixes(71.43e-3, 4e-6, 0.2)`` → ``"camera.doe_pitch_um ≥ 8.72 or camera.f_number ≥ 6.11"``.
    """
    return _count_fixes(aperture, pitch, focal, aperture_key, MAX_DOE_PIXELS, fewer=True)


def few_pixels_fixes(aperture: float, pitch: float, focal: float, aperture_key: str = "f_number") -> str:
    """What brings a DOE grid of ``aperture`` / ``pitch`` pixels (m, m) up to ``MIN_DOE_PIXELS``: a finer pitch,
    or a larger aperture in the scene's own key (as ``grid_fixes``), each rounded to three digits on the side that
    fits.

    Example: ``few_pixels_fixes(0.25e-3, 100e-6, 16e-3)`` → ``"camera.doe_pitch_um ≤ 15.6 or camera.f_number ≤
    10"``."""
    return _count_fixes(aperture, pitch, focal, aperture_key, MIN_DOE_PIXELS, fewer=False)


def _count_fixes(aperture: float, pitch: float, focal: float, aperture_key: str, pixels: int, fewer: bool) -> str:
    """The pitch, and the aperture in ``aperture_key``, that bring ``aperture`` / ``pitch`` to ``pixels`` DOE pixels
    (at most where ``fewer``, else at least), each rounded to three digits on the side that fits."""
    side = pixels * pitch  # the aperture the grid holds at this pitch
    up, down = (math.ceil, math.floor) if fewer else (math.floor, math.ceil)  # pitch and f-number; diameter
    pitch_cmp, diameter_cmp = ("≥", "≤") if fewer else ("≤", "≥")
    if aperture_key == "aperture_diameter_mm":
        change = f"camera.aperture_diameter_mm {diameter_cmp} {_round3(side * 1e3, down):g}"
    else:
        change = f"camera.f_number {pitch_cmp} {_round3(focal / side, up):g}"
    return f"camera.doe_pitch_um {pitch_cmp} {_round3(aperture / pixels * 1e6, up):g} or {change}"


def _round3(x: float, direction) -> float:
    """``x`` to three significant digits, rounded by ``direction`` (math.floor or math.ceil)."""
    step = 10.0 ** (math.floor(math.log10(x)) - 2)
    return round(direction(round(x / step, 9)) * step, 12)  # 4.98 / 0.01 is 498.00000000000006: not 499


def source_phase_step(cam, lam_min: float, z: float) -> float:
    """The largest change of a point source's phase between pupil samples one DOE pitch apart (rad), for a point
    at ``z`` metres and the shortest wavelength: the PSF routes refuse it above ``SOURCE_PHASE_LIMIT``."""
    import numpy as np

    from doefab.optics.pupil import source_path_difference

    r = np.linspace(0, cam.aperture_diameter / 2, 20001)
    opd = source_path_difference(r**2, z, cam.focus_distance)
    return float(np.max(np.abs(np.diff(opd))) * (cam.doe_pitch / (r[1] - r[0])) * 2 * math.pi / lam_min)


def steepest_plane(cam, lam_min: float, depths) -> tuple[float, float]:
    """(depth in metres, its ``source_phase_step``) of the plane whose point source's wavefront is steepest across
    the pupil: the nearest when it lies nearer than the focus, the farthest when that lies farther off in inverse
    depth (a point beyond the focus converges behind the sensor; ``inf`` is the plane wave).

    Example: on a camera focused at 0.3 m, of ``[0.5, 10.0]`` it is 10 m."""
    return max(((float(z), source_phase_step(cam, lam_min, z)) for z in depths), key=lambda zs: zs[1])


def pitch_fix(cam, pitch_max: float) -> list[str]:
    """``camera.doe_pitch_um ≤ …`` (a scene's way to a finer pupil sampling: one sample per DOE pixel), when the
    DOE grid that pitch gives stays within ``system.MAX_DOE_PIXELS``."""
    um = pitch_max * 1e6 * 0.99  # below the bound after rounding to 3 digits
    return [f"camera.doe_pitch_um ≤ {um:.3g}"] if cam.aperture_diameter / (um * 1e-6) <= MAX_DOE_PIXELS else []


def phase_step_fix(cam, lam_min: float, depths, factor: int = 1, limit: float | None = None) -> str:
    """The scene keys that bring the source's phase step per pupil sample below the limit at every plane of
    ``depths`` on ``cam``'s grid (a design grid coarsened by ``factor``: the DOE pitch it suggests is divided by
    it): the planes nearer the focus (a nearest depth farther away where a plane nearer than the focus is too steep,
    and a farthest depth nearer where one beyond it is: both where both are), or a finer DOE pitch (the step is
    proportional to it). The step is the wavefront's slope at the pupil's edge a,
    2π p / λ · |a / √(a² + z²) − a / √(a² + f²)| for a point at z with the focus at f; "" where every plane passes.
    ``limit``: the step allowed (rad; default ``SOURCE_PHASE_LIMIT``)."""
    from doefab.optics.psf import SOURCE_PHASE_LIMIT

    limit = SOURCE_PHASE_LIMIT if limit is None else limit
    steps = {float(z): source_phase_step(cam, lam_min, z) for z in depths}
    worst = max(steps.values())
    if worst <= limit:
        return ""
    a, f = cam.aperture_diameter / 2, cam.focus_distance
    room = limit * lam_min / (2 * math.pi * cam.doe_pitch)  # the slope the limit allows
    focus = 0.0 if math.isinf(f) else a / math.hypot(a, f)
    steep = [z for z, v in steps.items() if v > limit]
    bounds = []
    if any(z < f for z in steep):
        c = focus + room
        bounds.append(f"a nearest depth ≥ {a * math.sqrt(1 / c**2 - 1) * 1.01:.3g} m" if c < 1 else None)
    if any(z > f for z in steep):
        c = focus - room
        bounds.append(f"a farthest depth ≤ {a * math.sqrt(1 / c**2 - 1) * 0.99:.3g} m" if c > 0 else None)
    fixes = [" and ".join(bounds) + " (optics.depths_m)"] if bounds and None not in bounds else []
    fixes += pitch_fix(cam, cam.doe_pitch * limit / worst / factor)
    return " or ".join(fixes) or "depth planes nearer the focus distance"


def quick_sampling(doe_pixels: int, sampling: int, fits=None) -> int:
    """The design grid's coarsening under ``--quick``: of the factors up to 8 that divide the grid, are multiples
    of the scene's own ``sampling`` and pass ``fits(factor)`` (the PSF routes' sampling at that grid), the one
    nearest 4 (the larger on a tie) that leaves at least ``MIN_DOE_PIXELS``; the scene's own when none
    is. Example: ``quick_sampling(3200, 1) == 4``,
    ``quick_sampling(2234, 1) == 2`` (2234 = 2 · 1117)."""
    ok = [d for d in range(sampling, 9) if doe_pixels % d == 0 and d % sampling == 0
          and doe_pixels // d >= MIN_DOE_PIXELS and (fits is None or fits(d))]
    return min(ok, key=lambda d: (abs(d - 4), -d)) if ok else sampling


def design_camera(cam, factor: int):
    """The camera the design stage optimises on: the optimiser's own coarsening (``design.optimize.design_camera``,
    imported on use: it brings torch, which a scene's checks and the holder stage do without)."""
    from doefab.design.optimize import design_camera as coarsen

    return coarsen(cam, factor)


def design_grid_problems(cam, task, factor: int) -> list[tuple[str, float]]:
    """What the PSF routes would refuse on the design grid coarsened by ``factor``: a point at the steepest plane
    sampled too coarsely, or the window beyond the alias-free field."""
    from doefab.optics.psf import SOURCE_PHASE_LIMIT

    dcam = design_camera(cam, factor)
    lam_min = min(task.wavelengths(cam))
    out = []
    _, step = steepest_plane(dcam, lam_min, task.depths(cam))
    if step > SOURCE_PHASE_LIMIT:
        out.append(("step", step))
    alias = alias_free_px(dcam, lam_min)
    if task.kernel_size / 2 + 0.5 > alias:
        out.append(("alias", alias))
    return out


def design_factor_checks(scene: Scene, cam, task, factor: int, cfg: dict | None = None) -> list[str]:
    """A point at the steepest plane (``steepest_plane``) must be sampled finely enough on the full DOE grid and on
    the design grid (``design.sampling``, else the committed design's), and the window must stay inside the design
    grid's alias-free field: the design stage computes its PSFs there. Each fix is for the design grid, and one that
    the scene's optimiser takes (``nlopt_takes``; else with Adam)."""
    from doefab.optics.psf import SOURCE_PHASE_LIMIT

    lam_min = min(task.wavelengths(cam))
    factor = factor if factor >= 1 and cam.doe_pixels % factor == 0 else 1  # else ``sampling_checks`` says so
    dcam = design_camera(cam, factor)
    z, step = steepest_plane(cam, lam_min, task.depths(cam))
    dz = steepest_plane(dcam, lam_min, task.depths(cam))[0]
    depth_fix = phase_step_fix(dcam, lam_min, task.depths(cam), factor)
    if step > SOURCE_PHASE_LIMIT:
        if factor > 1:  # the fix above is the design grid's; the full grid alone asks less
            full_fix = phase_step_fix(cam, lam_min, task.depths(cam))
            depth_fix = (f"{depth_fix} (for the design grid, {cam.doe_pixels // factor} px at design.sampling "
                         f"{factor}), or design.sampling = 1 with {full_fix}")
        return [f"optics.depths_m: a point at {distance_text(z)} changes its phase by {step:.2f} rad "
                f"between DOE pixels at {lam_min * 1e9:.0f} nm, above the {SOURCE_PHASE_LIMIT:g} rad the PSF "
                f"routes sample: set {depth_fix}"]
    bad = design_grid_problems(cam, task, factor)
    if not bad or factor == 1:  # the design grid is the DOE grid, whose own checks name what it lacks
        return []
    fits = [d for d in range(1, factor) if cam.doe_pixels % d == 0 and not design_grid_problems(cam, task, d)]
    taken = [d for d in fits if nlopt_takes(scene, cam, cfg or {}, d)]
    grid_fix = (f"design.sampling = {max(taken)}" if taken else
                f'design.sampling = {max(fits)} with design.optimizer = "adam"' if fits else "design.sampling = 1")
    key = "design.sampling" if "sampling" in scene.design else "design.sampling (the committed design's)"
    what = "; ".join(f"a point at {distance_text(dz)} changes its phase by {v:.2f} rad between design pixels"
                     if k == "step" else f"optics.kernel_px {task.kernel_size} reaches beyond the alias-free field "
                     f"({2 * v - 1:.0f} px)" for k, v in bad)
    if any(k == "alias" for k, _ in bad):  # nearer planes do not widen the field: a finer pitch that fixes both
        bounds = [dcam.doe_pitch * v / (task.kernel_size / 2 + 0.5) for k, v in bad if k == "alias"]
        bounds += [dcam.doe_pitch * SOURCE_PHASE_LIMIT / v for k, v in bad if k == "step"]
        depth_fix = " or ".join(pitch_fix(cam, min(bounds) / factor))
    fix = " or ".join([grid_fix] + ([depth_fix] if depth_fix else []))
    return [f"{key} {factor}: the design grid ({cam.doe_pixels // factor} px of {dcam.doe_pitch * 1e6:.3g} µm) is "
            f"too coarse for the PSF routes ({what}): set {fix}"]


def nlopt_pixels(scene: Scene, cam, cfg: dict, factor: int) -> int | None:
    """The variables nlopt would be given on the design grid coarsened by ``factor``: the coded pixels of a pixel
    design whose ``design.optimizer`` (else the committed design's) is lbfgs or mma; None where nlopt does not run
    (Adam takes any grid; a radial profile's knots are few)."""
    from doefab.design.optimize import coded_mask, design_camera

    def setting(key, default):
        return scene.design.get(key, cfg.get(key, default))

    if setting("optimizer", "adam") == "adam" or setting("parameterization", "pixel") != "pixel":
        return None
    return int(coded_mask(design_camera(cam, factor)).sum())


def nlopt_takes(scene: Scene, cam, cfg: dict, factor: int) -> bool:
    """Whether the design stage's optimiser takes the design grid coarsened by ``factor`` (``nlopt_pixels``)."""
    from doefab.design.nloptrun import nlopt_takes_variables

    n = nlopt_pixels(scene, cam, cfg, factor)
    return n is None or nlopt_takes_variables(n)


def optimizer_checks(scene: Scene, cam, cfg: dict, task) -> list[str]:
    """nlopt's optimisers (``design.optimizer`` lbfgs, mma) take at most ``NLOPT_MAX_VARIABLES`` variables, a pixel
    design's coded pixels on its design grid: ``doefab run`` would stop at the design stage otherwise. The fix names
    the finest coarser ``design.sampling`` that nlopt takes and the PSF routes sample (``design_grid_problems``),
    else Adam alone."""
    from doefab.design.nloptrun import NLOPT_MAX_VARIABLES, nlopt_takes_variables

    factor = int(scene.design.get("sampling", cfg.get("sampling", 1)))
    if cam.doe_pixels % factor:
        return []  # ``sampling_checks`` names a factor that does not divide the grid
    n = nlopt_pixels(scene, cam, cfg, factor)  # counted once: a large grid's mask takes a while
    if n is None or nlopt_takes_variables(n):
        return []
    fits = next((f for f in range(factor + 1, 17) if cam.doe_pixels % f == 0 and nlopt_takes(scene, cam, cfg, f)
                 and not design_grid_problems(cam, task, f)), None)
    fix = " or ".join(([f"design.sampling = {fits}"] if fits else []) + ['design.optimizer = "adam"'])
    opt = scene.design.get("optimizer", cfg.get("optimizer"))
    return [f"design.optimizer {opt}: the {cam.doe_pixels // factor}² px design grid has "
            f"{n:,} coded pixels, above the {NLOPT_MAX_VARIABLES:,} variables "
            f"nlopt's optimisers take: set {fix}"]


def sampling_checks(scene: Scene, cam, cfg: dict) -> list[str]:
    """The design grid's coarsening (the scene's ``design.sampling``, else the committed design's) must divide
    the DOE grid and leave at least ``MIN_DOE_PIXELS``: ``doefab run`` would stop at the design stage otherwise
    (``--quick`` picks a factor that fits)."""
    from doefab.design.optimize import sampling_problem

    key = "design.sampling" if "sampling" in scene.design else "design.sampling (the committed design's)"
    factor = int(scene.design.get("sampling", cfg.get("sampling", 1)))
    problem = sampling_problem(cam.doe_pixels, factor, key)
    if problem is None and factor > 1 and cam.doe_pixels // factor < MIN_DOE_PIXELS:
        fits = [d for d in range(1, factor) if cam.doe_pixels % d == 0 and cam.doe_pixels // d >= MIN_DOE_PIXELS]
        problem = (f"{key} {factor} leaves a design grid of {cam.doe_pixels // factor} px, below the "
                   f"{MIN_DOE_PIXELS} a pattern needs: use {' or '.join(map(str, fits))}")
    return [problem] if problem else []
