"""The holder as a backend-neutral recipe of solids (millimetres), built by manifold3d or by cadquery.

A body is ``(adds, subs)``: the union of the added solids minus the union of the subtracted ones. The
solids are cylinders, frustums, prisms from 2-D polygons and a twisted prism (the thread). Both backends
evaluate the same recipe, so the mesh and the B-rep agree by construction and their agreement is a
test of each backend.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from holder_cad import derive
from holder_cad.params import HolderParams

__all__ = ["Cyl", "Cone", "Revolve", "Prism", "Twisted", "Body", "base_body", "cartridge_body", "coupon_bodies",
           "die_outline", "offset_convex", "thread_section", "COUPON_GRIP_MM"]

COUPON_GRIP_MM = 2.0  # the threaded coupon ring's grip rim beyond the thread


@dataclass(frozen=True)
class Cyl:
    r: float
    z0: float
    z1: float
    x: float = 0.0
    y: float = 0.0


@dataclass(frozen=True)
class Cone:
    r0: float
    r1: float
    z0: float
    z1: float


@dataclass(frozen=True)
class Revolve:
    """Solid of revolution of a closed (r, z) profile (r ≥ 0, counter-clockwise in the r–z plane)."""

    profile: tuple


@dataclass(frozen=True)
class Prism:
    points: tuple  # ((x, y), ...) counter-clockwise
    z0: float
    z1: float


@dataclass(frozen=True)
class Twisted:
    """Prism of a 2-D section twisted by ``twist_deg`` (counter-clockwise, +z) over z0..z1."""

    points: tuple
    z0: float
    z1: float
    twist_deg: float


@dataclass
class Body:
    name: str
    adds: list = field(default_factory=list)
    subs: list = field(default_factory=list)


def offset_convex(points: np.ndarray, d: float) -> np.ndarray:
    """Outward offset of a convex counter-clockwise polygon by ``d`` with mitred (sharp) corners."""
    p = np.asarray(points, float)
    n = len(p)
    nxt = np.roll(p, -1, axis=0)
    e = nxt - p
    normal = np.stack([e[:, 1], -e[:, 0]], 1) / np.linalg.norm(e, axis=1)[:, None]
    a = p + d * normal  # point on each offset edge line
    out = []
    for i in range(n):
        j = (i - 1) % n  # previous edge
        d1, d2 = e[j], e[i]
        m = np.array([[d1[0], -d2[0]], [d1[1], -d2[1]]])
        t = np.linalg.solve(m, a[i] - a[j])
        out.append(a[j] + t[0] * d1)
    return np.array(out)


def die_outline(p: HolderParams) -> np.ndarray:
    """Die outline in the cartridge frame (mm, CCW), as the mask set's dicing outline draws it
    (``doefab.diekey.die_outline``): a rectangle centred on the axis whose two corners on the coded half are
    chamfered, ``die_chamfer_mm`` at +y and half that at −y. The cartridge's top in print orientation is its lens
    side, and seen from there the coded half lies at x > 0 (the mask layout with the pattern toward the lens); a
    turned or flipped die does not fit the pocket.
    """
    from doefab.diekey import die_outline as outline

    return outline(p.die_width_mm, p.die_height_mm, p.die_chamfer_mm, coded_sign=1)


def thread_points(p: HolderParams) -> int:
    """Points a turn of the thread's section (``thread_section``): 120, or for a part of more than 128
    ``segments`` its segments up to 256 (see there)."""
    return 120 if p.segments <= 128 else min(int(p.segments), 256)


def thread_section(p: HolderParams, n: int | None = None) -> np.ndarray:
    """(n, 2) cross-section of a single-start right-hand thread with 45° flanks at z = 0.

    The radius at angle θ is the axial profile at z = −P·θ/2π; twisting the section by +360° per pitch
    sweeps it along the helix. ``n`` (None: ``thread_points``): about as finely as the part's circles. Its facets
    cut into the wall behind the root by r_root (1 − cos(π / n)) (120 points on a 150 mm thread: 0.025 mm, more than
    a 256-gon bore's facets give back), which the wall check allows for (``checks.facet_sag_mm`` at the coarser of
    the two); 256 points cut at most 0.006 mm on any thread allowed. The twisted mesh grows with n² (1024 points:
    the default holder took 98 s and 10 GB instead of 3.4 s), and the STEP path's time with n (128 points instead
    of 120: 4.5 → 6.3 s), hence 120 up to 128 segments.
    """
    n = thread_points(p) if n is None else int(n)
    pitch, depth = p.thread_pitch_mm, p.thread_depth_mm
    r_root = p.thread_root_radius_mm
    flat = (pitch - 2 * depth) / 2  # crest and root flats share what the flanks leave

    def profile(u):  # u = axial position within one pitch, mm → height above the root
        return np.interp(np.mod(u, pitch), [0, flat / 2, flat / 2 + depth, flat / 2 + depth + flat,
                                            pitch - flat / 2, pitch], [0, 0, depth, depth, 0, 0])

    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = r_root + profile(-pitch * theta / (2 * np.pi))
    return np.stack([r * np.cos(theta), r * np.sin(theta)], 1)


def _annular_sector(r_mid: float, width: float, a0: float, a1: float, n: int = 48) -> tuple:
    """Slot of radial ``width`` centred on radius r_mid from angle a0 to a1 (radians), rounded ends."""
    ri, ro = r_mid - width / 2, r_mid + width / 2
    ang = np.linspace(a0, a1, n)
    outer = [(ro * math.cos(a), ro * math.sin(a)) for a in ang]
    cap1 = [(r_mid * math.cos(a1) + width / 2 * math.cos(a1 + t), r_mid * math.sin(a1) + width / 2 * math.sin(a1 + t))
            for t in np.linspace(0, math.pi, 12)[1:-1]]
    inner = [(ri * math.cos(a), ri * math.sin(a)) for a in ang[::-1]]
    cap0 = [(r_mid * math.cos(a0) + width / 2 * math.cos(a0 + math.pi + t),
             r_mid * math.sin(a0) + width / 2 * math.sin(a0 + math.pi + t)) for t in np.linspace(0, math.pi, 12)[1:-1]]
    return tuple(outer + cap1 + inner + cap0)


def _notch(r_outer: float, angle: float, depth: float, width: float) -> tuple:
    """A V-notch cut into a rim at ``angle`` (radians), as a triangle reaching outside the rim."""
    c, s = math.cos(angle), math.sin(angle)
    tip = (c * (r_outer - depth), s * (r_outer - depth))
    out = r_outer + 1.0
    half = width / 2 / r_outer * (out / r_outer)
    a, b = angle - half, angle + half
    return (tip, (out * math.cos(a), out * math.sin(a)), (out * math.cos(b), out * math.sin(b)))


def _thread(p: HolderParams, body: Body) -> None:
    """The male thread from the bed (z = 0) to ``thread_length_mm``, its teeth chamfered where it starts on the bed:
    a cone from ``LEAD_IN_INSET_MM`` inside the root radius at z = 0, widening ``LEAD_IN_SLOPE`` mm per mm of
    height (39° from the axis: within the 45° that prints without support, facets included) to the full tooth
    about half a millimetre up, so the first layer's squash (elephant's foot) stays within the root and the
    thread starts in the lens without binding. (A cone through the root's own edge is a degenerate cut for the
    B-rep kernel.)"""
    t, r_in, slope = p.thread_length_mm, p.thread_root_radius_mm - derive.LEAD_IN_INSET_MM, derive.LEAD_IN_SLOPE
    body.adds.append(Twisted(tuple(map(tuple, thread_section(p))), 0.0, t, 360.0 * t / p.thread_pitch_mm))
    r_out = p.thread_major_radius_mm + 0.5
    body.subs.append(Revolve(((r_in - slope, -1.0), (r_out, -1.0), (r_out, (r_out - r_in) / slope))))


def _chamfer_foot(p: HolderParams) -> tuple[float, float]:
    """(radius, height) (mm) where the flange's 45° chamfer over the thread starts: just inside the thread's root,
    so no face overhangs, and high enough that the cone passes the lens's crest radius (``seat_radius_mm``) only at
    the thread's end: the base screws in until the filter face meets that plane."""
    r0 = p.thread_root_radius_mm - 0.02
    return r0, p.thread_length_mm - (p.seat_radius_mm - r0)


def _threaded_ring(p: HolderParams, body: Body, r_outer: float, top: float) -> None:
    """The thread, and over it a ring of radius ``r_outer`` up to ``top`` whose underside is the 45° chamfer from
    :func:`_chamfer_foot`; the bore through both."""
    _thread(p, body)
    r0, z_a = _chamfer_foot(p)
    body.adds.append(Revolve(((0.0, z_a), (r0, z_a), (r_outer, z_a + (r_outer - r0)), (r_outer, top), (0.0, top))))
    body.subs.append(Cyl(p.bore_radius_mm, -1.0, top + 1.0))


def _slip_plate(p: HolderParams, body: Body, plate_mm: float, sleeve_mm: float) -> None:
    """A plate of the flange's diameter, ``plate_mm`` thick on the bed (its lens side up), the sleeve over the
    barrel ``sleeve_mm`` long above it, and the bore through the plate."""
    rin = p.barrel_diameter_mm / 2 + p.clearance_mm
    body.adds.append(Cyl(p.flange_diameter_mm / 2, 0.0, plate_mm))
    body.adds.append(Cyl(rin + p.wall_mm, plate_mm - 1e-3, plate_mm + sleeve_mm))
    body.subs.append(Cyl(rin, plate_mm, plate_mm + sleeve_mm + 1.0))
    body.subs.append(Cyl(p.bore_radius_mm, -1.0, plate_mm + 1.0))


def base_body(p: HolderParams) -> Body:
    """The base ring in print orientation (flat face on the bed at z = 0)."""
    rf = p.flange_diameter_mm / 2
    body = Body("base")
    if p.mount == "thread":
        top = p.thread_length_mm + p.flange_height_mm
        _threaded_ring(p, body, rf, top)
        r0, z_a = _chamfer_foot(p)
        # the pilot holes stop wall_mm (measured square to the 45° chamfer) above the chamfer; the graduations
        # stay wall_mm clear of it
        z_lo, z0 = p.thread_length_mm + p.pilot_stop_mm, z_a + (rf - r0) + p.wall_mm
    else:
        top = p.flange_height_mm
        _slip_plate(p, body, top, p.sleeve_length_mm)
        z_lo = z0 = -1.0  # through the plate
    r_hole = p.pilot_hole_mm / 2
    for k in range(4):  # M2 pilot holes for the cartridge's lock screws
        a = math.pi / 4 + k * math.pi / 2
        body.subs.append(Cyl(r_hole, z_lo, top + 1.0, p.pilot_radius_mm * math.cos(a),
                             p.pilot_radius_mm * math.sin(a)))
    # 10° graduations (deeper every 90°) on the flange rim
    for k in range(36):
        depth = 1.0 if k % 9 == 0 else 0.5
        body.subs.append(Prism(_notch(rf, math.radians(10 * k), depth, 0.8), z0, top + 1.0))
    return body


def cartridge_body(p: HolderParams) -> Body:
    """The DOE cartridge in print orientation: flange on the bed (z = 0), lens-side end at the top."""
    rf = p.flange_diameter_mm / 2
    cf = p.cartridge_flange_mm
    top = cf + p.cartridge_length_mm  # the lens-side face
    body = Body("cartridge")
    body.adds.append(Cyl(rf, 0.0, cf))
    body.adds.append(Cyl(p.cartridge_radius_mm, cf - 1e-3, top))
    pocket = offset_convex(die_outline(p), p.clearance_mm)
    die_top = top - p.washer_recess_mm  # the DOE face, toward the lens; washers sit on the die edge above it
    body.subs.append(Prism(tuple(map(tuple, pocket)), die_top - p.die_thickness_mm, top + 1.0))
    r_hole = p.clear_aperture_mm / 2 + p.seat_margin_mm
    body.subs.append(Cyl(r_hole, -1.0, top + 1.0))
    # toward the scene, below a straight step (wall_mm of material under the seat's rim), the hole flares at the
    # field's half-angle: the light of the whole field reaches the whole aperture
    z = die_top - p.die_thickness_mm - p.flare_step_mm
    body.subs.append(Cone(r_hole + (z + 1.0) * math.tan(math.radians(p.field_half_angle_deg)), r_hole, -1.0, z))
    # retention: two M2 screws beside the pocket (±x side centres), washers recessed to overlap the die edge
    for sx in (-1, 1):
        cx = sx * p.screw_offset_mm
        body.subs.append(Cyl(p.pilot_hole_mm / 2, die_top - derive.RETENTION_DEPTH_MM, top + 1.0, cx, 0.0))
        rw = p.washer_recess_half_mm  # recess: a rectangle from the pocket wall (square corners)
        edge = p.die_width_mm / 2 + p.clearance_mm - 0.01
        x0, x1 = (edge, cx + rw) if sx > 0 else (cx - rw, -edge)
        body.subs.append(Prism(((x0, -rw), (x1, -rw), (x1, rw), (x0, rw)), die_top, top + 1.0))
    # two arc slots for the lock screws, 100° each, centred on ±x: whatever angle the thread stops at, a
    # pilot hole (every 90°) lies under each slot
    for a0 in (0.0, math.pi):
        body.subs.append(Prism(_annular_sector(p.pilot_radius_mm, p.screw_clearance_mm, a0 - math.radians(50),
                                               a0 + math.radians(50)), -1.0, cf + 1.0))
    # index notches on the split-line direction (the DOE's y axis): 12 and 6 o'clock
    for a in (math.pi / 2, -math.pi / 2):
        body.subs.append(Prism(_notch(rf, a, 2.0, 1.6), -1.0, cf + 1.0))
    return body


def _coupon_thread_ring(p: HolderParams) -> Body:
    """The base's thread and bore under a narrow grip rim (the thread plus ``COUPON_GRIP_MM``, over a 45° chamfer
    and ``wall_mm``), without the flange, its lock-screw holes and graduations: the thread's fit and the flange
    face's seat on the lens, and the cartridge's slide in the bore, for about half the base's plastic."""
    ring = Body("coupon_ring")
    (r0, z_a), rg = _chamfer_foot(p), p.thread_major_radius_mm + COUPON_GRIP_MM
    _threaded_ring(p, ring, rg, z_a + (rg - r0) + p.wall_mm)
    return ring


def coupon_bodies(p: HolderParams) -> list[Body]:
    """Fit-test coupon, quick to print: a thread ring with a grip rim (or a thin plate and a short sleeve) and a
    die pocket."""
    if p.mount == "thread":
        ring = _coupon_thread_ring(p)
    else:  # the base's plate, thin, and a short sleeve over the barrel (the base's own, without its screw holes)
        ring = Body("coupon_ring")
        _slip_plate(p, ring, derive.PILOT_DEPTH_MM, min(p.sleeve_length_mm, 4.0))
    w = p.die_width_mm / 2 + p.clearance_mm + p.wall_mm + 1.0
    h = p.die_height_mm / 2 + p.clearance_mm + p.wall_mm + 1.0
    t = p.die_thickness_mm + 0.05 + p.wall_mm
    pocket_block = Body("coupon_pocket")
    pocket_block.adds.append(Prism(((-w, -h), (w, -h), (w, h), (-w, h)), 0.0, t))
    pocket = offset_convex(die_outline(p), p.clearance_mm)
    pocket_block.subs.append(Prism(tuple(map(tuple, pocket)), t - p.die_thickness_mm - 0.05, t + 1.0))
    pocket_block.subs.append(Cyl(p.clear_aperture_mm / 2 + p.aperture_margin_mm, -1.0, t + 1.0))
    return [ring, pocket_block]
