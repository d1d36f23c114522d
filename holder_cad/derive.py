"""The holder dimensions that follow from the lens's thread (or barrel) and the die when they are not given (mm).

A parameter left out (``None``) takes the value these rules give; a parameter that is given is kept, and one
that conflicts is refused by :class:`holder_cad.params.HolderParams` with the value these rules would choose.

- ``thread_pitch_mm``: the commonest pitch of a filter thread of that diameter: 0.5 mm up to 40.5 mm, 0.75 mm
  up to 82 mm, 1.0 mm above (some lenses differ, e.g. M37 × 0.75: measure yours and set it).
- ``thread_depth_mm``: 0.4 × the pitch (45° flanks leave 0.1 × pitch flats at crest and root).
- ``thread_length_mm``: 2.5 mm, or the least tenth of a millimetre more that gives ``MIN_FULL_TURNS`` turns of
  full tooth between the lead-in (``lead_in_mm``) and the flange's chamfer (2.8 mm for a 1.0 mm pitch).
- ``flange_diameter_mm``: the smallest whole millimetre that holds the thread (or sleeve) and the lock-screw
  holes and slots with ``wall_mm`` on both sides.
- ``flange_height_mm``: threaded base: the smallest half millimetre above the 45° chamfer plus ``wall_mm``
  that leaves the lock-screw pilot holes ``PILOT_DEPTH_MM`` deep; slip-fit plate: ``SLIP_PLATE_MM``.
- ``washer_recess_mm``: the least tenth of a millimetre that sinks the retention washers into the cartridge's
  lens-side end and keeps the M2 screw heads on them ``HEAD_GLASS_CLEARANCE_MM`` clear of the lens glass.

Functions take a parameter set whose other dimensions are already resolved (duck-typed, any object with the
``HolderParams`` fields and properties).
"""

from __future__ import annotations

import math

__all__ = ["DERIVED", "COMMON_FILTER_THREADS_MM", "next_filter_thread_mm", "PILOT_DEPTH_MM", "SLIP_PLATE_MM",
           "standard_pitch_mm", "standard_depth_mm", "thread_clearance_mm", "flank_clearance_mm", "thread_warnings",
           "PRINT_TOLERANCE_MM",
           "FILTER_PITCHES_MM", "COMMON_BED_MM",
           "least_thread_play_mm", "ISO_DEPTH",
           "widest_aperture_mm", "die_spread_mm", "seat_margin_mm", "LEDGE_MM", "RETENTION_DEPTH_MM",
           "MAX_FIELD_HALF_ANGLE_DEG", "DIE_INDEX_MIN", "min_flange_diameter_mm", "min_flange_height_mm",
           "flange_diameter_mm", "flange_height_mm", "max_flange_diameter_mm", "HEAD_GLASS_CLEARANCE_MM",
           "washer_recess_mm", "LEAD_IN_INSET_MM", "LEAD_IN_SLOPE", "lead_in_mm", "MIN_FULL_TURNS",
           "full_tooth_turns", "thread_length_mm", "groove_filled_mm", "length_for_turns_mm"]

PILOT_DEPTH_MM = 2.0  # an M2 lock screw bites at least its own diameter into the base
SLIP_PLATE_MM = 6.0  # the slip-fit base's plate
_EPS = 1e-9
# the common photographic filter threads (mm), the sizes step-up rings come in
COMMON_FILTER_THREADS_MM = (25.0, 27.0, 28.0, 30.5, 34.0, 37.0, 39.0, 40.5, 43.0, 46.0, 49.0, 52.0, 55.0, 58.0,
                            62.0, 67.0, 72.0, 77.0, 82.0, 86.0, 95.0, 105.0, 112.0, 122.0, 127.0)

# how each derived parameter follows (the key table and the holder page say the same)
DERIVED = {
    "thread_pitch_mm": "from thread_diameter_mm: 0.5 up to 40.5, 0.75 up to 82, 1.0 above",
    "thread_depth_mm": "0.4 × thread_pitch_mm",
    "thread_length_mm": "2.5, or the least tenth of a mm more giving two turns of full tooth between the lead-in "
                        "and the flange's chamfer",
    "thread_clearance_mm": "0.2165 × thread_pitch_mm + (layer_mm + 0.05) / 2 for the default tooth (its 45° flanks "
                           "clear the ISO 60° groove by layer_mm + 0.05 axially: 0.075 and 0.15 mm at 0.1 mm layers)",
    "flange_diameter_mm": "the least whole mm holding the thread or sleeve and the lock screws with wall_mm",
    "flange_height_mm": f"thread: the least half mm over the chamfer plus wall_mm with {PILOT_DEPTH_MM:g} mm deep "
                        f"pilot holes; slip: {SLIP_PLATE_MM:g}",
    "washer_recess_mm": "the least tenth of a mm that sinks the washers and keeps the screw heads 0.2 mm clear of "
                        "the lens glass",
}
# the retention screws' heads sweep a circle over the lens's front glass as the base is screwed in: they stay this
# far in front of the glass's vertex plane (twice a printed part's length tolerance, about 0.1 mm)
HEAD_GLASS_CLEARANCE_MM = 0.2


# the thread's lead-in where it starts on the bed: a cone from LEAD_IN_INSET_MM inside the root radius, widening
# LEAD_IN_SLOPE mm per mm of height to the full tooth
LEAD_IN_INSET_MM = 0.05
LEAD_IN_SLOPE = 0.8
# the least turns of full tooth in a full groove (between the lead-in and the flange's chamfer) that hold the
# holder square in the lens's thread
MIN_FULL_TURNS = 2.0
_THREAD_LENGTH_MM = 2.5  # the default thread length, where it gives MIN_FULL_TURNS


def lead_in_mm(p) -> float:
    """Height (mm) of the thread's lead-in, from the bed to where its cone reaches the full tooth's crest:
    (``thread_depth_mm`` + ``LEAD_IN_INSET_MM``) / ``LEAD_IN_SLOPE``.

    Example: 0.4375 mm for the 0.3 mm tooth of a 0.75 mm pitch."""
    return (p.thread_depth_mm + LEAD_IN_INSET_MM) / LEAD_IN_SLOPE


def groove_filled_mm(p) -> float:
    """Height (mm) where the flange's 45° chamfer, which reaches the lens's crest radius (``seat_radius_mm``) at
    the thread's end (the lens's filter face), reaches the groove's bottom: ``thread_length_mm`` less the seat
    radius's height over the root. Above it the groove is partly filled; the turns counted as bearing end there
    (a margin: the filling stays inside the lens's crest radius below the thread's end)."""
    return p.thread_length_mm - _chamfer_fill_mm(p)


def _chamfer_fill_mm(p) -> float:
    """How far below the thread's end (mm) the flange's 45° chamfer reaches the groove's bottom: its seat radius's
    height over the root."""
    return p.seat_radius_mm - p.thread_root_radius_mm


def full_tooth_turns(p) -> float:
    """Turns of full tooth in a full groove, between the lead-in's top and the flange's chamfer: the turns that
    bear in the lens's thread. Example: 2.57 for the default 2.5 mm thread of a 0.75 mm pitch
    ((2.5 − 0.1313 − 0.4375) / 0.75)."""
    return (groove_filled_mm(p) - lead_in_mm(p)) / p.thread_pitch_mm


def length_for_turns_mm(p, turns: float) -> float:
    """The thread length (mm) that bears ``turns`` turns of full tooth (:func:`full_tooth_turns` inverted): the
    turns, the lead-in and the height the flange's chamfer fills (its seat radius over the root). Example:
    2.7125 mm for two turns of a 1.0 mm pitch (2 + 0.5625 + 0.15)."""
    return turns * p.thread_pitch_mm + lead_in_mm(p) + _chamfer_fill_mm(p)


def thread_length_mm(p) -> float:
    """The derived thread length (mm): 2.5 mm, or the least tenth of a millimetre more that gives ``MIN_FULL_TURNS``
    turns of full tooth between the lead-in and the flange's chamfer (``p``'s pitch and tooth depth resolved).

    Example: 2.5 mm for a 0.75 mm pitch; 2.8 mm for a 1.0 mm pitch (0.5625 mm lead-in, 2 mm, 0.15 mm chamfer)."""
    return max(_THREAD_LENGTH_MM, math.ceil(10 * length_for_turns_mm(p, MIN_FULL_TURNS) - 1e-6) / 10)


LEDGE_MM = 0.5  # the least floor ring round the hole that the die rests on
RETENTION_DEPTH_MM = 3.4  # the die-retention screws' pilot holes below the washers' seat (the DOE's face): 1.7 × ⌀
MAX_FIELD_HALF_ANGLE_DEG = 45.0  # the flared hole in front of the DOE: its overhang prints without support up to 45°
# the lowest refractive index of a DOE substrate (calcium fluoride, 1.434 at 550 nm): inside the die an off-axis ray
# spreads by at most thickness × tan(asin(sin θ / DIE_INDEX_MIN)) between the hole and the DOE's chrome stop
DIE_INDEX_MIN = 1.43
FLARE_SLACK_MM = 0.1  # the hole's least radial clearance of the field's light, for a print's undersized holes


def die_spread_mm(die_thickness_mm: float, angle_deg: float) -> float:
    """How far (mm) the light of a field point ``angle_deg`` off axis moves sideways crossing the die, refracted at
    ``DIE_INDEX_MIN`` (Snell's law). Example: ``round(die_spread_mm(1.0, 24.0), 3)`` → 0.297."""
    return die_thickness_mm * math.tan(math.asin(math.sin(math.radians(angle_deg)) / DIE_INDEX_MIN))


def seat_margin_mm(aperture_margin_mm: float, die_thickness_mm: float, field_half_angle_deg: float,
                   wall_mm: float) -> float:
    """How much wider than the clear aperture (radius, mm) the hole is where the die rests on it:
    ``aperture_margin_mm``, or where the light of the field's edge needs more, its spread inside the die (refracted
    at ``DIE_INDEX_MIN``) plus ``FLARE_SLACK_MM`` plus what the flare gains over the ``wall_mm`` high step the hole
    keeps straight below the seat (so the seat's rim has wall_mm of material under it).

    Example: ``round(seat_margin_mm(0.3, 1.0, 24.0, 1.2), 2)`` → 0.93 (mm)."""
    if field_half_angle_deg <= 0:
        return aperture_margin_mm
    flare = wall_mm * math.tan(math.radians(field_half_angle_deg))
    return max(aperture_margin_mm, die_spread_mm(die_thickness_mm, field_half_angle_deg) + FLARE_SLACK_MM + flare)


def widest_aperture_mm(die_side_mm: float, seat_margin: float) -> float:
    """The widest clear aperture a die of this (shorter) side holds: the hole ``seat_margin`` (``seat_margin_mm``)
    larger than the aperture all round where the die rests, and a ``LEDGE_MM`` ledge round it to rest on (an
    aperture must stay below this)."""
    return die_side_mm - 2 * LEDGE_MM - 2 * seat_margin


def next_filter_thread_mm(diameter_mm: float) -> float:
    """The smallest common filter thread (mm) of at least ``diameter_mm`` (a step-up ring's size), or
    ``diameter_mm`` rounded up to half a millimetre beyond the list."""
    return next((d for d in COMMON_FILTER_THREADS_MM if d >= diameter_mm - _EPS), math.ceil(2 * diameter_mm) / 2)


COMMON_BED_MM = 220.0  # a common FDM printer's bed side (mm): a print layout wider than it is warned of
FILTER_PITCHES_MM = (0.5, 0.75, 1.0)  # the pitches photographic filter threads are cut with


def thread_warnings(diameter_mm: float, pitch_mm: float) -> list[str]:
    """What is unusual about a filter thread of this nominal diameter and pitch (mm): a size no common filter has,
    a pitch no filter thread is cut with — likely a misread lens (each line names the nearest common ones).

    Example: ``thread_warnings(49.3, 0.75)`` → one line naming 49 and 52 mm."""
    out = []
    if not any(abs(diameter_mm - d) < _EPS for d in COMMON_FILTER_THREADS_MM):
        below = [d for d in COMMON_FILTER_THREADS_MM if d < diameter_mm]
        above = [d for d in COMMON_FILTER_THREADS_MM if d > diameter_mm]
        near = " and ".join(f"{d:g}" for d in (below[-1:] + above[:1]))
        out.append(f"thread_diameter_mm {diameter_mm:g} is no common filter thread (nearest {near} mm): check "
                   f"the size on the lens's front ring or cap; a custom thread is built as given")
    if not any(abs(pitch_mm - q) < _EPS for q in FILTER_PITCHES_MM):
        pitches = ", ".join(f"{q:g}" for q in FILTER_PITCHES_MM)
        out.append(f"thread_pitch_mm {pitch_mm:g} is no filter-thread pitch ({pitches} mm): leave it out to "
                   f"take the size's standard pitch, {standard_pitch_mm(diameter_mm):g} mm")
    return out


def standard_pitch_mm(thread_diameter_mm: float) -> float:
    """The commonest pitch (mm) of a photographic filter thread of this nominal diameter (mm)."""
    if thread_diameter_mm <= 40.5:
        return 0.5
    return 0.75 if thread_diameter_mm <= 82.0 else 1.0


ISO_DEPTH = 0.54127  # an ISO metric thread's basic depth of engagement, × pitch: (D − D1) / 2


def least_thread_play_mm(pitch_mm: float, depth_mm: float) -> float:
    """The least radial play (mm) at which the printed tooth (45° flanks, ``depth_mm`` deep, its crest flat
    (pitch − 2·depth) / 2) fits the lens's ISO 60° groove, 0.75 × pitch wide at the female thread's minor diameter:
    the tooth's width there, crest + 2·(0.541·P − play), at most that (0.2165 × pitch for the 0.4 × pitch tooth).

    Example: ``round(least_thread_play_mm(0.75, 0.3), 4)`` → 0.1622 (mm)."""
    crest = (pitch_mm - 2 * depth_mm) / 2
    return max(0.0, ISO_DEPTH * pitch_mm - (0.75 * pitch_mm - crest) / 2)


PRINT_TOLERANCE_MM = 0.05  # how true an FDM print's edges are (mm, either way)


def flank_clearance_mm(layer_mm: float) -> float:
    """The axial clearance (mm) the printed tooth keeps from the lens's groove flanks where they meet, printed at
    ``layer_mm`` layers: a layer's edge stands up to half a layer proud of each 45° flank (both flanks at once: one
    layer) plus ``PRINT_TOLERANCE_MM``; a tooth with the least play alone (a few µm) binds once printed.

    Example: ``flank_clearance_mm(0.1)`` → 0.15 (mm)."""
    return round(layer_mm + PRINT_TOLERANCE_MM, 6)


def thread_clearance_mm(pitch_mm: float, depth_mm: float, layer_mm: float = 0.1) -> float:
    """The printed thread's radial play (mm) in a filter thread of this pitch and tooth depth, printed at
    ``layer_mm`` layers: the least at which its 45° tooth clears the lens's 60° groove (``least_thread_play_mm``)
    plus half :func:`flank_clearance_mm` (each 0.01 mm of radial play widens the 45° tooth's axial gap there by
    0.02 mm): 0.2165 × pitch + 0.075 mm for the 0.4 × pitch tooth at 0.1 mm layers, which leaves 42 % of the ISO
    basic depth (``ISO_DEPTH``) engaged at M49 × 0.75.

    Example: ``round(thread_clearance_mm(0.75, 0.3), 4)`` → 0.2372 (mm)."""
    return round(least_thread_play_mm(pitch_mm, depth_mm) + flank_clearance_mm(layer_mm) / 2, 6)


def standard_depth_mm(pitch_mm: float) -> float:
    """Tooth depth (mm) of a 45°-flank thread of this pitch: 0.4 × pitch, below the pitch / 2 a V would reach."""
    return round(0.4 * pitch_mm, 6)


def min_flange_diameter_mm(p) -> float:
    """The least flange diameter (mm): the lock-screw ring (pilot holes, cartridge slots) with wall_mm inside and
    outside it, around the bore (thread) or outside the sleeve (slip); a thread's flange also overhangs its
    crest by wall_mm."""
    hole = max(p.screw_clearance_mm, p.pilot_hole_mm)
    if p.mount == "thread":  # the screws sit mid-flange, between the bore and the rim
        r = max(p.bore_radius_mm + hole + 2 * p.wall_mm, p.thread_major_radius_mm + p.wall_mm)
    else:  # the screws sit just outside the sleeve
        pilot_r = p.sleeve_outer_radius_mm + p.wall_mm + p.pilot_hole_mm / 2
        r = max(pilot_r + p.screw_clearance_mm / 2 + p.wall_mm, p.sleeve_outer_radius_mm + p.wall_mm)
    return 2 * r


def flange_diameter_mm(p) -> float:
    """The derived flange diameter (mm): :func:`min_flange_diameter_mm` rounded up to a whole millimetre."""
    return float(math.ceil(min_flange_diameter_mm(p) - _EPS))


def min_flange_height_mm(p) -> float:
    """The least flange height (mm) for ``p``'s flange diameter: a threaded base's 45° chamfer plus wall_mm, and
    pilot holes PILOT_DEPTH_MM deep above the chamfer (they stop wall_mm, square to it, short of it); a
    slip-fit plate is drilled through, so it needs PILOT_DEPTH_MM."""
    if p.mount != "thread":
        return PILOT_DEPTH_MM
    return max(p.chamfer_height_mm + p.wall_mm, PILOT_DEPTH_MM + p.pilot_stop_mm)


def flange_height_mm(p) -> float:
    """The derived flange height (mm): :func:`min_flange_height_mm` rounded up to half a millimetre (threaded
    base), SLIP_PLATE_MM (slip fit)."""
    if p.mount != "thread":
        return SLIP_PLATE_MM
    return math.ceil(2 * min_flange_height_mm(p) - _EPS) / 2


def max_flange_diameter_mm(p, height_mm: float) -> float:
    """The largest whole-millimetre flange diameter (mm) whose :func:`min_flange_height_mm` is at most
    ``height_mm`` (a threaded base: its chamfer grows with the flange)."""
    seat, wall = p.seat_radius_mm, p.wall_mm
    by_chamfer = height_mm - wall + seat
    by_pilots = 2 * (height_mm - PILOT_DEPTH_MM - p.pilot_hole_mm / 2 - wall * math.sqrt(2) + seat) - p.bore_radius_mm
    return float(math.floor(2 * min(by_chamfer, by_pilots) + _EPS))


def washer_recess_mm(p) -> float:
    """The derived washer recess (mm): the least tenth of a millimetre that sinks each retention washer
    (``washer_thickness_mm``) into the cartridge's lens-side end and keeps the screw head on it (``screw_head_mm``
    tall) ``HEAD_GLASS_CLEARANCE_MM`` in front of the lens glass's vertex plane, ``glass_gap_mm`` beyond that end.
    For the defaults (0.3 mm washer, 1.3 mm head, glass 1.0 mm beyond the thread's tip) it is 0.8 mm."""
    washer = p.washer_thickness_mm
    need = max(washer, washer + p.screw_head_mm - p.glass_gap_mm + HEAD_GLASS_CLEARANCE_MM)
    return math.ceil(10 * need - 1e-6) / 10
