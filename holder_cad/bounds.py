"""Bounds on the holder's derived quantities that decide whether it fits and works (``fit_bounds``)."""

from __future__ import annotations

import math

from holder_cad import derive
from holder_cad.ranges import ENGAGED_MIN, PARAM_RANGES, HolderError, least_key_chamfer_mm

__all__ = ["fit_bounds", "recess_chamfer_problem", "die_too_large_problem", "flange_diameter_problem",
           "flange_height_problem", "clear_aperture_problem", "then_problem"]

_TRYING = [False]  # a fix being tried: its own refusals name their fixes without trying them in turn


def then_problem(p, **changes) -> str | None:
    """None when ``p`` with ``changes`` builds, else what it is refused for next (a fix is tried one level deep:
    None too while another fix is being tried)."""
    if _TRYING[0]:
        return None
    _TRYING[0] = True
    try:
        p.replace(**changes)
        return None
    except HolderError as exc:
        return str(exc)
    finally:
        _TRYING[0] = False


def clear_aperture_problem(p) -> str | None:
    """A clear aperture and its margins that do not fit inside the die with a ledge, with the fixes that build
    (each tried; where none does, each with what it is refused for next); None when it fits."""
    side = min(p.die_width_mm, p.die_height_mm)
    ledge = derive.widest_aperture_mm(side, p.seat_margin_mm)
    if p.clear_aperture_mm < ledge:
        return None
    aperture = math.floor(100 * ledge - 1) / 100
    die = math.ceil(p.clear_aperture_mm + side - ledge + 0.01)
    fixes = {f"clear_aperture_mm = {aperture:g} or less": then_problem(p, clear_aperture_mm=aperture),
             f"die_width_mm and die_height_mm to {die:g} or more": then_problem(p, die_width_mm=die,
                                                                                 die_height_mm=die)}
    good = [f for f, next_problem in fixes.items() if next_problem is None]
    offer = good or [f"{f} (then: {next_problem})" for f, next_problem in fixes.items()]
    if p.seat_margin_mm > p.aperture_margin_mm:
        offer.append("a smaller field_half_angle_deg (the light of a wider field spreads more inside the die)")
    return (f"clear_aperture_mm ({p.clear_aperture_mm:g}) + margins ({p.seat_margin_mm:.2f} mm round it where the "
            f"die sits, for the field's light) does not fit inside the die ({p.die_width_mm:g} × "
            f"{p.die_height_mm:g} mm) with a {derive.LEDGE_MM:g} mm ledge: set " + ", or ".join(offer))


def _param_row(p, name: str) -> tuple:
    lo, hi, why = PARAM_RANGES[name]
    return name, getattr(p, name), lo, hi, "mm", why


def _play_fix(p) -> str:
    """What the thread's play must be: enough for the printed 45° tooth to clear the lens's 60° groove, little
    enough to leave ``ENGAGED_MIN`` of the basic thread depth engaged."""
    least = derive.least_thread_play_mm(p.thread_pitch_mm, p.thread_depth_mm)
    lo = math.ceil(2000 * least) / 2000
    hi = math.floor(2000 * (1 - ENGAGED_MIN) * derive.ISO_DEPTH * p.thread_pitch_mm) / 2000
    if "thread_clearance_mm" in p.derived:  # the play followed from the layer height: a finer layer keeps it
        layer = math.floor(100 * (2 * (hi - least) - derive.PRINT_TOLERANCE_MM)) / 100
        finer = (f"print the thread at layer_mm = {layer:g} or less (its flank clearance at {p.layer_mm:g} mm layers, "
                 f"{derive.flank_clearance_mm(p.layer_mm):g} mm, leaves too little engaged), or "
                 if layer >= PARAM_RANGES["layer_mm"][0] else "")
        return (f"the printed thread's play must let its 45° tooth clear the lens's 60° groove and leave a quarter "
                f"of the basic depth engaged: {finer}set thread_clearance_mm between {lo:g} and {hi:g}")
    return (f"the printed thread's play must let its 45° tooth clear the lens's 60° groove and leave a quarter of "
            f"the basic depth engaged: set thread_clearance_mm between {lo:g} and {hi:g}, or leave it out")


def _thread_lengths_mm(p) -> tuple[float, float]:
    """(least, longest) thread length (mm, tenths) that bears ``MIN_FULL_TURNS``–20 turns of full tooth between
    the lead-in and the flange's chamfer and keeps its tip ``HEAD_GLASS_CLEARANCE_MM`` in front of the lens glass
    (and within the parameter's range)."""
    lo = math.ceil(10 * derive.length_for_turns_mm(p, derive.MIN_FULL_TURNS) - 1e-6) / 10
    glass = p.lens_face_to_glass_mm - derive.HEAD_GLASS_CLEARANCE_MM
    longest = min(derive.length_for_turns_mm(p, 20.0), glass, PARAM_RANGES["thread_length_mm"][1])
    hi = math.floor(10 * longest + 1e-6) / 10
    return lo, hi


def _thread_fix(p, what: str) -> str:
    """How to make the thread bear two turns and stop short of the glass (``what``: the bound's own words)."""
    lo, hi = _thread_lengths_mm(p)
    if lo <= hi:
        derived = lo <= derive.thread_length_mm(p) <= hi
        return f"{what}: set thread_length_mm between {lo:g} and {hi:g}" + (", or leave it out" if derived else "")
    return (f"{what}: two turns of the {p.thread_pitch_mm:g} mm pitch need a {lo:g} mm thread, but the lens glass, "
            f"lens_face_to_glass_mm ({p.lens_face_to_glass_mm:g} mm) behind the filter face, leaves room for "
            f"{hi:g} mm: measure lens_face_to_glass_mm again, or mount the holder on the barrel (mount = \"slip\")")


def recess_chamfer_problem(p) -> str | None:
    """What is wrong (None: nothing) when the coded half's washer recess reaches past the pocket's straight side
    into its keyed chamfer: the pocket's chamfer, offset by the clearance, leaves that side up to
    h/2 − die_chamfer_mm + clearance·(√2 − 1) from the die's middle, and a recess beyond it leaves a
    knife-edge."""
    rw = p.washer_recess_half_mm
    straight = p.die_height_mm / 2 - p.die_chamfer_mm + p.clearance_mm * (math.sqrt(2) - 1)
    if rw <= straight + 1e-9:
        return None
    chamfer = math.floor(10 * (p.die_chamfer_mm - rw + straight) + 1e-9) / 10
    washer = math.floor(10 * 2 * (straight - p.clearance_mm) + 1e-9) / 10
    overlap_least = 2 * (0.5 + p.screw_offset_mm - p.die_width_mm / 2)  # washers must overlap the die by 0.5 mm
    taller = math.ceil(2 * (rw + p.die_chamfer_mm - p.clearance_mm * (math.sqrt(2) - 1)) - 1e-9)
    fixes = ([f"die_chamfer_mm = {chamfer:g} or less"] if chamfer > least_key_chamfer_mm(p.clearance_mm) else []) + (
        [f"washer_diameter_mm = {washer:g} or less"] if washer >= overlap_least else []) + [
        f"die_height_mm = {taller:g} or more"]
    return (f"the retention washers' recesses ({rw:g} mm either side of the die's middle) reach the pocket's keyed "
            f"chamfer (die_chamfer_mm {p.die_chamfer_mm:g} on a {p.die_height_mm:g} mm die), where they would leave a "
            f"knife-edge of plastic: set " + ", or ".join(fixes))


def _head_fix(p) -> str:
    """How to keep the retention screws' heads clear of the lens glass."""
    need = derive.washer_recess_mm(p)
    return (f"the M2 screw heads ({p.screw_head_mm:g} mm on {p.washer_thickness_mm:g} mm washers) sweep the "
            f"lens's front glass as the base turns: set washer_recess_mm = {need:g} or more (the DOE then sits "
            f"{p.glass_gap_mm + need:.2f} mm from the glass), or leave it out (it follows), or use a lower head")


def fit_bounds(p, doe_to_lens_mm: float | None = None) -> list[dict]:
    """Bounds on the derived quantities that decide whether the holder fits and works (millimetres).

    ``doe_to_lens_mm``: a measured value (from the built mesh) instead of the formula's. Each entry:
    quantity, value, min, max, unit, ok, fix.
    """
    d = p.doe_to_lens_mm if doe_to_lens_mm is None else doe_to_lens_mm
    rows = [
        ("doe_to_lens_mm", d, 0.2, p.max_doe_to_lens_mm, "mm",
         "the DOE must sit close to, but clear of, the lens glass: check thread_length_mm, washer_recess_mm and "
         "lens_face_to_glass_mm"),
        ("lens_side_end_to_glass_mm", round(d - p.washer_recess_mm, 6), derive.HEAD_GLASS_CLEARANCE_MM, 1e3, "mm",
         _thread_fix(p, "the thread's tip (and the cartridge's end, flush with it) must stop short of the lens "
                        "glass as the base turns") if p.mount == "thread" else
         "the cartridge's end must stop short of the lens glass: check lens_face_to_glass_mm"),
        ("screw_head_to_glass_mm", round(d - p.washer_thickness_mm - p.screw_head_mm, 6),
         derive.HEAD_GLASS_CLEARANCE_MM, 1e3, "mm", _head_fix(p)),
        ("die_to_pocket_clearance_mm", p.clearance_mm, *PARAM_RANGES["clearance_mm"][:2], "mm",
         "clearance_mm: " + PARAM_RANGES["clearance_mm"][2]),
        ("washer_recess_mm", p.washer_recess_mm, p.nozzle_mm / 2, PARAM_RANGES["washer_recess_mm"][1], "mm",
         PARAM_RANGES["washer_recess_mm"][2]),
        ("retention_hole_floor_mm", p.cartridge_flange_mm + p.cartridge_length_mm - p.washer_recess_mm
         - derive.RETENTION_DEPTH_MM, p.wall_mm, 1e3, "mm", f"the retention screws' pilot holes, "
         f"{derive.RETENTION_DEPTH_MM:g} mm below the washers' seat, must stop wall_mm short of the cartridge's "
         "scene-side face: a smaller washer_recess_mm, or a taller cartridge (cartridge_flange_mm, flange_height_mm)"),
        ("die_seat_thickness_mm", p.cartridge_flange_mm + p.cartridge_length_mm - p.washer_recess_mm - p.die_thickness_mm,
         p.wall_mm, 1e3, "mm", "material under the die pocket must be at least wall_mm: a smaller "
                               "washer_recess_mm or die_thickness_mm, or a longer thread/flange"),
        ("wall_mm", p.wall_mm, p.nozzle_mm, 10.0, "mm", "wall_mm between one nozzle line and 10 mm"),
    ]
    if p.mount == "thread":
        rows += [
            _param_row(p, "thread_pitch_mm"),
            ("thread_full_tooth_turns", derive.full_tooth_turns(p), derive.MIN_FULL_TURNS, 20.0, "turns",
             _thread_fix(p, f"the thread must bear {derive.MIN_FULL_TURNS:g}–20 turns of full tooth between its "
                            f"{derive.lead_in_mm(p):.2f} mm lead-in and the flange's chamfer")),
            ("thread_clearance_mm", p.thread_clearance_mm, derive.least_thread_play_mm(p.thread_pitch_mm,
                                                                                       p.thread_depth_mm),
             (1 - ENGAGED_MIN) * derive.ISO_DEPTH * p.thread_pitch_mm, "mm", _play_fix(p)),
            _param_row(p, "thread_depth_mm"),
        ]
    return [{"quantity": q, "value": float(v), "min": lo, "max": hi, "unit": u, "ok": bool(lo <= v <= hi), "fix": fix}
            for q, v, lo, hi, u, fix in rows]


def die_too_large_problem(p) -> str:
    """The refusal of a die the cartridge cannot hold, with a thread (or barrel) and a die that work."""
    c, wall, rw, need = p.clearance_mm, p.wall_mm, p.washer_recess_half_mm, p.cartridge_need_mm
    # the largest square die whose pocket and washer recesses fit this cartridge
    reach = p.screw_offset_mm - p.die_width_mm / 2  # pocket edge to screw axis
    room = p.cartridge_radius_mm - wall
    half = min(room / math.sqrt(2) - c, math.sqrt(max(room ** 2 - rw ** 2, 0.0)) - reach - rw)
    side = math.floor(20 * half) / 10
    holds = side - 2 * wall - 2 * p.aperture_margin_mm > p.clear_aperture_mm  # it still takes the DOE
    die = f", or use a die of at most {side:g} × {side:g} mm (die_width_mm, die_height_mm)" if holds else ""
    what = (f"the die ({p.die_width_mm:g} × {p.die_height_mm:g} mm), its pocket and the washer recesses "
            f"need a cartridge of radius {need:.2f} mm, this one has {p.cartridge_radius_mm:.2f} mm")
    if p.mount == "slip":
        barrel = math.ceil(2 * (need + c + wall + 3.0) * 2 - 1e-9) / 2
        return f"{what}: set barrel_diameter_mm = {barrel:g} or more{die}"
    thread = 2 * (need + 2 * c + wall + p.thread_depth_mm)
    if "thread_depth_mm" in p.derived and "thread_pitch_mm" in p.derived:  # a larger thread's teeth
        thread = 2 * (need + 2 * c + wall + derive.standard_depth_mm(derive.standard_pitch_mm(thread)))
    thread = derive.next_filter_thread_mm(thread)
    return (f"{what}: set thread_diameter_mm = {thread:g} or more (a step-up ring from the lens's "
            f"{p.thread_diameter_mm:g} mm thread){die}")


def flange_diameter_problem(p) -> str | None:
    """A flange too narrow for the thread's bore (or the sleeve) and the lock screws, with the diameter that holds
    them; None when it fits."""
    least = derive.min_flange_diameter_mm(p)
    if p.flange_diameter_mm >= least - 1e-9:
        return None
    what = (f"the {p.thread_diameter_mm:g} mm thread's bore" if p.mount == "thread" else
            f"the sleeve over the {p.barrel_diameter_mm:g} mm barrel")
    src = "thread" if p.mount == "thread" else "barrel"
    return (f"flange_diameter_mm ({p.flange_diameter_mm:g}) is below {least:.2f} mm, the least that holds {what} "
            f"and the lock-screw holes and slots with wall_mm ({p.wall_mm:g} mm) on both sides: set "
            f"flange_diameter_mm = {derive.flange_diameter_mm(p):g}, or leave it out (it follows from the {src})")


def flange_height_problem(p) -> str | None:
    """A flange too low for its chamfer and pilot holes (or a derived one above the range), with the fix; None when
    it fits."""
    hi = PARAM_RANGES["flange_height_mm"][1]
    if "flange_height_mm" in p.derived and p.flange_height_mm > hi:
        return (f"flange_diameter_mm ({p.flange_diameter_mm:g}) needs a {p.flange_height_mm:g} mm flange height "
                f"over its 45° chamfer, above the {hi:g} mm allowed: set flange_diameter_mm = "
                f"{derive.max_flange_diameter_mm(p, hi):g} or less, or leave it out")
    need = derive.min_flange_height_mm(p)
    if p.flange_height_mm >= need - 1e-9:
        return None
    why = (f"the 45° chamfer ({p.chamfer_height_mm:.2f} mm) plus wall_mm and lock-screw pilot holes "
           f"{derive.PILOT_DEPTH_MM:g} mm deep above it" if p.mount == "thread" else
           f"lock-screw pilot holes {derive.PILOT_DEPTH_MM:g} mm deep")
    return (f"flange_height_mm ({p.flange_height_mm:g}) is too low: {why} need {need:.2f} mm: set "
            f"flange_height_mm = {derive.flange_height_mm(p):g}, or leave it out (it follows from the flange)")
