"""The holder's parameters one at a time: each length's range (mm), the field angle, the mount and the facets
(``given_problem``), the error every refusal raises (``HolderError``) and the margins the keyed pocket and the thread
are held to."""

from __future__ import annotations

import math

from doefab.diekey import KEY_PROUD_MM, LEAST_CLEARANCE_MM, least_key_chamfer_mm
from holder_cad import derive

__all__ = ["HolderError", "PARAM_RANGES", "given_problem", "KEY_PROUD_MM", "ENGAGED_MIN", "least_key_chamfer_mm"]


ENGAGED_MIN = 0.25  # the least share of the ISO basic thread depth the printed thread must engage


class HolderError(ValueError):
    """Impossible or unprintable holder parameters (the message names the parameters)."""


# every length parameter's range (mm), checked first so a value out of range is named before anything derived
# from it; the fit bounds the README states (die clearance 0.05–1 mm, thread pitch 0.25–1.5 mm, tooth depth
# 0.1–0.8 mm, wall up to 10 mm, washer recess up to 3 mm) and sanity bounds on the rest (filter threads and lens
# barrels of 20–150 mm, parts that fit a printer bed)
PARAM_RANGES = {
    "thread_diameter_mm": (20.0, 150.0, "filter threads; 49 for the EF 50 mm f/1.8 STM"),
    "thread_pitch_mm": (0.25, 1.5, "filter threads have pitches 0.5–1.0 mm"),
    "thread_depth_mm": (0.1, 0.8, "a printable tooth of a filter thread"),
    "thread_length_mm": (0.5, 30.0, "the thread's length, lead-in included"),
    "barrel_diameter_mm": (20.0, 150.0, "a lens front barrel"),
    "sleeve_length_mm": (1.0, 100.0, "the slip-fit sleeve"),
    "lens_face_to_glass_mm": (0.01, 50.0, "filter face to front glass: measure your lens"),
    "die_width_mm": (2.0, 100.0, "the fused-silica die"),
    "die_height_mm": (2.0, 100.0, "the fused-silica die"),
    "die_thickness_mm": (0.1, 10.0, "the fused-silica die"),
    "die_chamfer_mm": (0.1, 50.0, "the keyed die corner"),
    "clear_aperture_mm": (0.5, 100.0, "the DOE clear aperture"),
    "aperture_margin_mm": (0.01, 10.0, "extra radius of the hole"),
    "clearance_mm": (LEAST_CLEARANCE_MM, 1.0,
                     "below 0.05 mm a printed pocket will not take the die, above 1 mm the die rattles"),
    "thread_clearance_mm": (0.01, 0.5, "the printed thread's radial play in the lens's filter thread"),
    "wall_mm": (0.1, 10.0, "between one nozzle line and 10 mm"),
    "nozzle_mm": (0.1, 2.0, "a printer nozzle"),
    "layer_mm": (0.02, 0.4, "a printer's layer height (the thread's, at least)"),
    "flange_diameter_mm": (20.0, 250.0, "fits a printer bed"),
    "flange_height_mm": (0.5, 50.0, "the base flange"),
    "cartridge_flange_mm": (0.5, 50.0, "the cartridge flange"),
    "screw_clearance_mm": (0.5, 10.0, "an M2 clearance hole is 2.4 mm"),
    "pilot_hole_mm": (0.3, 10.0, "an M2 pilot hole is 1.7 mm"),
    "washer_diameter_mm": (1.0, 30.0, "an M2 washer is 5–6 mm"),
    "washer_thickness_mm": (0.05, 2.0, "an M2 washer is 0.3 mm thick"),
    "screw_head_mm": (0.3, 5.0, "an M2 cheese head is 1.3 mm tall, a pan head 1.6, a socket head 2"),
    "washer_recess_mm": (0.05, 3.0, "the recess holds an M2 washer (0.3 mm) and must stay within the cartridge"),
    "max_doe_to_lens_mm": (0.2, 50.0, "the farthest the DOE may sit from the lens"),
}


def given_problem(values: dict) -> str | None:
    """What is wrong with given holder parameters taken one at a time (None: nothing): each length positive,
    finite and in its range, the mount and the facet count known. The checks between parameters (the die in its
    pocket, the thread's teeth, the flange) are :class:`HolderParams`'."""
    errs = [f"{k} must be a positive length in mm, got {v!r}" for k, v in values.items() if k.endswith("_mm") and (
        isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0)]
    if errs:
        return "; ".join(errs)
    out = [f"{k} {values[k]:g} is outside {lo:g}–{hi:g} mm ({why})" for k, (lo, hi, why) in PARAM_RANGES.items()
           if k in values and values[k] is not None and not lo <= values[k] <= hi]
    if out:
        return "; ".join(out)
    if values.get("mount", "thread") not in ("thread", "slip"):
        return f"mount must be 'thread' or 'slip', got {values['mount']!r}"
    angle = values.get("field_half_angle_deg", 0.0)
    widest = derive.MAX_FIELD_HALF_ANGLE_DEG
    if isinstance(angle, bool) or not isinstance(angle, (int, float)) or not 0 <= angle <= widest:
        return (f"field_half_angle_deg must be a number of degrees in 0–{widest:g} (the half-angle of the lens's "
                f"field of view: atan(sensor half-diagonal / focal length)), got {angle!r}")
    seg = values.get("segments", 128)
    if isinstance(seg, bool) or not isinstance(seg, int) or not 32 <= seg <= 1024:
        return f"segments must be an integer in 32..1024 (facets per circle), got {seg!r}"
    return None
