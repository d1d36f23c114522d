"""The die and holder a scene asks for: the die its mask set is drawn on (``scene_die_m``; its key and thickness,
``scene_die``), the field the holder's hole passes (``scene_field_half_angle_deg``), the holder's parameters with
the DOE's die and aperture (``scene_holder``), and the checks of that holder before any work (``holder_checks``)."""

from __future__ import annotations

import math

from doefab.errors import DoefabError
from doefab.pipeline.scene import Scene

__all__ = ["scene_die_m", "least_die_m",
           "scene_die", "scene_field_half_angle_deg", "scene_holder", "holder_checks", "die_checks",
           "holder_warnings"]


def scene_die_m(scene: Scene, cam) -> float:
    """The die the scene's mask set is drawn on (m): the square ``holder.die_width_mm`` = ``die_height_mm`` the scene
    gives where it is at least ``least_die_m``, else the smallest whole-millimetre square, 12 mm (the prototype's) at
    least, that ``least_die_m`` allows.

    Example: the prototype's 8.64 mm DOE is drawn on a 12 mm die (its marks alone fit 11 mm, its pocket needs 12)."""
    from doefab.fabrication.marks import smallest_die_m

    least = least_die_m(scene, cam)
    given = {scene.holder.get("die_width_mm"), scene.holder.get("die_height_mm")}
    if len(given) == 1 and None not in given and given.pop() * 1e-3 >= least - 1e-9:  # a square die, given
        return scene.holder["die_width_mm"] * 1e-3
    return max(least, smallest_die_m(*_die_args(scene, cam), floor_m=12e-3))


def least_die_m(scene: Scene, cam) -> float:
    """The smallest whole-millimetre square die (m) that holds the DOE grid with a 1 mm margin and the marks of its
    masks (``fabrication.marks.smallest_die_m``) and whose holder pocket holds the DOE's clear aperture
    (``holder_cad.derive.widest_aperture_mm``)."""
    from doefab.fabrication.marks import smallest_die_m

    from holder_cad.derive import MAX_FIELD_HALF_ANGLE_DEG, seat_margin_mm, widest_aperture_mm
    from holder_cad.params import HolderParams

    h = {k: scene.holder.get(k, getattr(HolderParams, k))
         for k in ("aperture_margin_mm", "die_thickness_mm", "wall_mm")}
    field = scene_field_half_angle_deg(scene, cam)
    h["field_half_angle_deg"] = min(HolderParams.field_half_angle_deg if field is None else field,
                                    MAX_FIELD_HALF_ANGLE_DEG)  # a wider field is refused (holder_checks)
    aperture_mm = cam.aperture_diameter * 1e3
    holder_mm = math.floor(aperture_mm - widest_aperture_mm(0.0, seat_margin_mm(**h))) + 1  # the least whole mm
    return smallest_die_m(*_die_args(scene, cam), floor_m=holder_mm * 1e-3)


def _die_args(scene: Scene, cam) -> tuple:
    """``smallest_die_m``'s aperture, pattern extent, CD (m) and mask count for the scene's DOE."""
    from doefab.fabrication.process import DEFAULT_LEVELS, mask_count

    n_masks = mask_count(int(scene.fabrication.get("n_levels", DEFAULT_LEVELS)))
    return cam.aperture_diameter, cam.doe_pixels * cam.doe_pitch, cam.doe_pitch, n_masks


def scene_die(scene) -> tuple[float, float]:
    """(the die key's larger chamfer, the substrate's thickness), metres, that the scene's holder takes
    (``holder.die_chamfer_mm``, ``holder.die_thickness_mm``): the mask set's dicing outline draws the first
    (``doefab.diekey``) and its manifest states the second."""
    from doefab.diekey import DEFAULT_CHAMFER_MM, DEFAULT_THICKNESS_MM

    chamfer = scene.holder.get("die_chamfer_mm", DEFAULT_CHAMFER_MM)
    return float(chamfer) * 1e-3, float(scene.holder.get("die_thickness_mm", DEFAULT_THICKNESS_MM)) * 1e-3


def scene_field_half_angle_deg(scene: Scene, cam) -> float | None:
    """The field's half-angle (degrees) the holder's hole in front of the DOE must pass: the scene's
    ``holder.field_half_angle_deg`` when given, else the sensor's, atan(``camera.sensor_diagonal_mm`` / 2 / the
    sensor distance), to a thousandth of a degree, when that is given; None leaves the holder's default.

    Example (a full-frame sensor 50 mm behind the lens): atan(21.63 / 50) → 23.4°."""
    if "field_half_angle_deg" in scene.holder:
        return scene.holder["field_half_angle_deg"]
    diagonal_mm = scene.camera.get("sensor_diagonal_mm")
    if diagonal_mm is None:
        return None
    return round(math.degrees(math.atan(diagonal_mm * 1e-3 / 2 / cam.sensor_distance)), 3)


def scene_holder(scene: Scene, cam) -> dict:
    """The holder's parameters (mm): the scene's ``[holder]`` keys over the DOE's own die and clear aperture and the
    sensor's field (:func:`scene_field_half_angle_deg`), so every dimension not given follows from the thread, the
    DOE and the camera (``holder_cad`` derives the rest)."""
    die_mm = round(scene_die_m(scene, cam) * 1e3, 6)
    field = scene_field_half_angle_deg(scene, cam)
    return {"die_width_mm": die_mm, "die_height_mm": die_mm, "clear_aperture_mm": round(cam.aperture_diameter * 1e3, 6),
            **({"field_half_angle_deg": field} if field is not None else {}), **scene.holder}


def holder_warnings(scene: Scene, cam) -> list[str]:
    """What is unusual about the holder the run would build (``HolderParams.warnings``: a thread size or pitch no
    filter has), each naming its scene key; none when the holder stage is not run or its parameters are refused
    (``holder_checks`` says why)."""
    if "holder" not in scene.stages:
        return []
    from holder_cad.params import HolderError, HolderParams

    try:
        return [f"holder.{note}" for note in HolderParams(**scene_holder(scene, cam)).warnings]
    except (HolderError, DoefabError):
        return []


def die_checks(scene: Scene, cam) -> list[str]:
    """The die of a mask set without a holder stage (``holder_checks`` checks it with the holder): a given one
    square and at least ``least_die_m``, and the die key's chamfer below half of it."""
    if "masks" not in scene.stages or "holder" in scene.stages:
        return []
    default = scene_die_m(scene, cam) * 1e3
    given = [scene.holder.get("die_width_mm"), scene.holder.get("die_height_mm")]
    return _die_problem(scene, cam, [default if v is None else v for v in given])


def _die_problem(scene: Scene, cam, sides: list) -> list[str]:
    """A given die that is not square or smaller than the mask set needs (with a holder stage: the least square die
    the holder also takes; a die that follows the DOE is left to the holder's own check, which names what else it
    lacks), and a die key's chamfer (``holder.die_chamfer_mm``) too large for the die."""
    least_mm = least_die_m(scene, cam) * 1e3
    if "holder" in scene.stages and {"die_width_mm", "die_height_mm"} & set(scene.holder):
        least_mm = _holder_least_die_mm(scene, cam, least_mm)  # a die the scene gives: the one the holder takes
    if sides[0] != sides[1] or sides[0] < least_mm - 1e-6:
        return [f"holder.die_width_mm {sides[0]:g} and die_height_mm {sides[1]:g}: the mask set is drawn on a square "
                f"die of at least {least_mm:g} mm (the DOE grid with a 1 mm margin, its marks and the holder's "
                f"{'pocket and washers' if 'holder' in scene.stages else 'pocket'}): set both to "
                f"{max(least_mm, *sides):g}, or leave them out (they follow the DOE: "
                f"{scene_die_m(scene, cam) * 1e3:g} mm)"]
    from doefab.diekey import chamfer_problem

    problem = chamfer_problem(min(sides), scene_die(scene)[0] * 1e3)
    return [f"holder.die_chamfer_mm: {problem}"] if problem else []


def _holder_least_die_mm(scene: Scene, cam, least_mm: float) -> float:
    """The least whole-millimetre square die, from ``least_mm``, that the scene's holder takes (its washers reach
    over the die); ``least_mm`` where none within 40 mm does (the holder's own check then says why)."""
    from holder_cad.params import HolderError, HolderParams

    params = scene_holder(scene, cam)
    for die in range(math.ceil(least_mm - 1e-6), math.ceil(least_mm - 1e-6) + 40):
        try:
            HolderParams(**{**params, "die_width_mm": float(die), "die_height_mm": float(die)})
            return float(die)
        except (HolderError, DoefabError):
            continue
    return least_mm


def holder_checks(scene: Scene, cam) -> list[str]:
    """The holder the run would build, checked with the DOE's die and aperture (as the holder stage builds it)."""
    if "holder" not in scene.stages:
        return []
    from holder_cad.derive import MAX_FIELD_HALF_ANGLE_DEG
    from holder_cad.params import HolderError, HolderParams

    params, out = scene_holder(scene, cam), []
    aperture_mm = cam.aperture_diameter * 1e3
    out += _die_problem(scene, cam, [params["die_width_mm"], params["die_height_mm"]])
    widest = MAX_FIELD_HALF_ANGLE_DEG
    if "field_half_angle_deg" not in scene.holder and params.get("field_half_angle_deg", 0.0) > widest:
        out.append(f"camera.sensor_diagonal_mm {scene.camera['sensor_diagonal_mm']:g} at a sensor distance of "
                   f"{cam.sensor_distance * 1e3:.4g} mm sees {params['field_half_angle_deg']:g}° off the axis, more "
                   f"than the {widest:g}° the holder's flared hole prints without support: set "
                   f"holder.field_half_angle_deg (at most {widest:g}; the field's corners beyond it are vignetted)")
    if params["clear_aperture_mm"] < aperture_mm * (1 - 1e-6):
        out.append(f"holder.clear_aperture_mm {params['clear_aperture_mm']:g} is smaller than the DOE's clear "
                   f"aperture ({aperture_mm:.4g} mm): the holder would clip the DOE; leave it out (it follows the "
                   f"DOE) or set it to {math.ceil(aperture_mm * 100) / 100:g} or more")
    if out:
        return out
    try:
        HolderParams(**params)
    except (HolderError, DoefabError) as exc:
        sensor = "field_half_angle_deg" not in scene.holder and "field_half_angle_deg" in params
        why = (f" (its {params['field_half_angle_deg']:g}° follows from camera.sensor_diagonal_mm: set "
               "holder.field_half_angle_deg)") if sensor and "field_half_angle" in str(exc) else ""
        return [f"holder: {exc}{why}; or leave \"holder\" out of stages (a holder of your own)"]
    return []
