"""Holder parameters. Units: millimetres (the CAD convention) — every length field ends in ``_mm``.

The part is two bodies printed separately, each flat on the bed and support-free:
- the **base ring**: a male filter thread (default M49 × 0.75, 45° flanks so every overhang is ≤ 45°) or a
  slip-fit sleeve, a 45°-chamfered flange, a cylindrical bore for the cartridge, four M2 pilot holes and
  10° graduation notches on its rim;
- the **cartridge**: a flange that rests on the base and a body that reaches down the bore to the lens side,
  holding the fused-silica die in a keyed pocket (two unequal chamfered die corners: the die fits one way only,
  not rotated, not flipped), with a clear aperture, two M2 retention screws whose washers overlap the die edge,
  two 100° arc slots centred on ±x (any rotation can be locked on the base's pilot holes: the thread's
  start angle does not matter) and two index notches at ±y, on the split-line direction.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from doefab.diekey import DEFAULT_CHAMFER_MM, DEFAULT_THICKNESS_MM
from holder_cad import derive
from holder_cad.bounds import (clear_aperture_problem, die_too_large_problem, fit_bounds, flange_diameter_problem,
                               flange_height_problem, recess_chamfer_problem, then_problem)
from holder_cad.ranges import PARAM_RANGES, HolderError, given_problem, least_key_chamfer_mm

__all__ = ["HolderParams", "HolderError", "fit_bounds", "PARAM_RANGES", "given_problem"]


@dataclass(frozen=True)
class HolderParams:
    """All dimensions in millimetres.

    Attributes:
        mount: ``"thread"`` (male filter thread into the lens) or ``"slip"`` (sleeve over the front barrel).
        thread_diameter_mm: nominal filter thread diameter (49 for the Canon EF 50 mm f/1.8 STM).
        thread_pitch_mm: thread pitch (by default the commonest for the diameter: 0.75 for 49 mm).
        thread_depth_mm: tooth height (by default 0.4 × pitch; 45° flanks).  thread_length_mm: the thread's length
            (by default 2.5, or more for two full-tooth turns above the lead-in).
        barrel_diameter_mm: outer diameter of the lens front barrel (slip fit only).
        sleeve_length_mm: slip-fit sleeve length.
        lens_face_to_glass_mm: from the lens's filter face (or barrel front) to the front glass vertex; the
            DOE-to-lens distance follows from it (measure your lens; 3.5 is an estimate for the EF 50/1.8 STM).
        die_width_mm, die_height_mm, die_thickness_mm: the fused-silica die (12 × 12 × 1 fits the 8.64 mm
            aperture and the mask set's marks).  die_chamfer_mm: the larger of the two chamfered die corners
            that key the die (``doefab.diekey``: the coded half's, this one at +y, the other half as large).
        clear_aperture_mm: DOE clear aperture (8.64).  aperture_margin_mm: extra radius of the hole.
        field_half_angle_deg: the half-angle of the field of view (degrees) the hole in front of the DOE passes
            unvignetted: it flares toward the scene at this angle (24: the prototype's 50 mm lens on a full-frame
            sensor, atan(21.6 / 50) = 23.4°; at most 45°, the steepest overhang that prints without support).
        clearance_mm: fit clearance per side (die in pocket, cartridge in bore, sleeve on barrel).
        thread_clearance_mm: the male thread's outer radius below the nominal: at least 0.2165 × pitch, for the
            printed 45° tooth to clear the lens's 60° groove, and at most what leaves a quarter of the ISO basic
            depth (0.541 × pitch) engaged; by default 0.075 mm more than the least (0.15 mm axial clearance at
            the flanks at 0.1 mm layers, ``derive.flank_clearance_mm``: a print's layer steps and tolerance).
        wall_mm: minimum wall (≥ the nozzle width).  nozzle_mm: printer nozzle width.  layer_mm: the layer height
            the base's thread is printed at (its flank clearance follows: ``derive.flank_clearance_mm``).
        flange_diameter_mm: outer diameter of both flanges (by default the least that holds the lock screws).
        flange_height_mm: the base flange (by default the least over the chamfer and the pilot holes).
        cartridge_flange_mm: its flange's height.  screw_clearance_mm, pilot_hole_mm: M2 clearance, pilot hole ⌀.
        washer_diameter_mm, washer_thickness_mm: the retention washers (6 × 0.3 mm).  screw_head_mm: the M2
            retention screws' head height (1.3: an ISO 1207 or ISO 14580 cheese head; pan 1.6, socket 2.0).
        washer_recess_mm: how deep the washers and the DOE's face sit below the cartridge's lens-side end (by
            default the least tenth of a mm that keeps the screw heads 0.2 mm clear of the lens glass).
        max_doe_to_lens_mm: the farthest the DOE may sit in front of the lens glass (the split-aperture optics
            assume it close to the aperture; 5 mm keeps the PSF change small, see the tolerance study).
        segments: facets of a full circle (mesh path).

    The seven parameters of :data:`holder_cad.derive.DERIVED` default to ``None``: they then follow from the
    thread (or barrel) and the die by the rules of :mod:`holder_cad.derive`, and :attr:`derived` names them.
    Every derived quantity that decides the fit has a bound (:func:`fit_bounds`); a parameter that violates
    one is refused before anything is built, with the parameter to change and a value that works.
    """

    mount: str = "thread"
    thread_diameter_mm: float = 49.0
    thread_pitch_mm: float | None = None
    thread_depth_mm: float | None = None
    thread_length_mm: float | None = None
    barrel_diameter_mm: float = 56.0
    sleeve_length_mm: float = 8.0
    lens_face_to_glass_mm: float = 3.5
    die_width_mm: float = 12.0
    die_height_mm: float = 12.0
    die_thickness_mm: float = DEFAULT_THICKNESS_MM
    die_chamfer_mm: float = DEFAULT_CHAMFER_MM
    clear_aperture_mm: float = 8.64
    aperture_margin_mm: float = 0.3
    field_half_angle_deg: float = 24.0
    clearance_mm: float = 0.25
    thread_clearance_mm: float | None = None
    wall_mm: float = 1.2
    nozzle_mm: float = 0.4
    layer_mm: float = 0.1
    flange_diameter_mm: float | None = None
    flange_height_mm: float | None = None
    cartridge_flange_mm: float = 2.4
    screw_clearance_mm: float = 2.4
    pilot_hole_mm: float = 1.7
    washer_diameter_mm: float = 6.0
    washer_thickness_mm: float = 0.3
    screw_head_mm: float = 1.3
    washer_recess_mm: float | None = None
    max_doe_to_lens_mm: float = 5.0
    segments: int = 128

    def __post_init__(self) -> None:
        object.__setattr__(self, "_derived", tuple(n for n in derive.DERIVED if getattr(self, n) is None))
        self._check_given()
        self._resolve("thread_pitch_mm", derive.standard_pitch_mm(self.thread_diameter_mm))
        self._resolve("thread_depth_mm", derive.standard_depth_mm(self.thread_pitch_mm))
        self._resolve("thread_clearance_mm", derive.thread_clearance_mm(self.thread_pitch_mm, self.thread_depth_mm,
                                                                        self.layer_mm))
        self._resolve("thread_length_mm", derive.thread_length_mm(self))  # its chamfer's seat follows the play
        self._check_die_and_thread()
        self._resolve("flange_diameter_mm", derive.flange_diameter_mm(self))
        self._check_flange_diameter()
        self._resolve("flange_height_mm", derive.flange_height_mm(self))
        self._check_flange_height()
        self._resolve("washer_recess_mm", derive.washer_recess_mm(self))
        self._check_flare()
        bad = [b for b in fit_bounds(self) if not b["ok"]]
        if bad:
            raise HolderError("; ".join(f"{b['quantity']} = {b['value']:.3g} {b['unit']} is outside "
                                        f"{b['min']:g}–{b['max']:g} {b['unit']} ({b['fix']})" for b in bad))

    @property
    def derived(self) -> tuple:
        """Names of the parameters that were not given and follow from the others (:mod:`holder_cad.derive`)."""
        return self._derived

    def _resolve(self, name: str, value: float) -> None:
        if name in self._derived:
            object.__setattr__(self, name, float(value))

    def _check_given(self) -> None:
        """Each given length positive, finite and in its range; the mount and the facet count known."""
        given = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in self._derived}
        problem = given_problem(given)
        if problem:
            raise HolderError(problem)

    def _check_die_and_thread(self) -> None:
        """The die, its pocket, the washers and the thread's teeth: each conflict names a value that works."""
        if self.wall_mm < self.nozzle_mm:
            raise HolderError(f"wall_mm ({self.wall_mm:g}) is below nozzle_mm ({self.nozzle_mm:g}): a printer "
                              f"cannot make walls thinner than one line: set wall_mm = {self.nozzle_mm:g} or more")
        side = min(self.die_width_mm, self.die_height_mm)
        problem = clear_aperture_problem(self)
        if problem:
            raise HolderError(problem)
        least = least_key_chamfer_mm(self.clearance_mm)
        if self.die_chamfer_mm >= 0.5 * side:
            good = math.ceil(10 * least + 1e-9) / 10  # the least chamfer that keys: within the half side, if any
            fix = (f"set die_chamfer_mm = {good:g}" if good < 0.5 * side else
                   f"a larger die or a smaller clearance_mm: no chamfer below half the side keys it at "
                   f"clearance_mm {self.clearance_mm:g} (it needs more than {least:.2f} mm)")
            raise HolderError(f"die_chamfer_mm ({self.die_chamfer_mm:g}) must be less than half the die's shorter "
                              f"side ({side:g} mm): {fix}")
        if self.die_chamfer_mm <= least:
            raise HolderError(f"die_chamfer_mm ({self.die_chamfer_mm:g}) is too small to key the die with "
                              f"clearance_mm {self.clearance_mm:g}: a flipped die would still fit the pocket; set "
                              f"die_chamfer_mm = {math.ceil(10 * least + 1e-9) / 10:g} or more")
        if self.thread_depth_mm * 2 >= self.thread_pitch_mm:
            raise HolderError(f"thread_depth_mm ({self.thread_depth_mm:g}) is too deep for thread_pitch_mm "
                              f"({self.thread_pitch_mm:g}) with 45° flanks (depth < pitch / 2): set "
                              f"thread_depth_mm = {derive.standard_depth_mm(self.thread_pitch_mm):g}")
        overlap = self.die_width_mm / 2 - (self.screw_offset_mm - self.washer_diameter_mm / 2)
        if overlap < 0.5:
            need = math.ceil(2 * (self.washer_diameter_mm / 2 + 0.5 - overlap) * 2 - 1e-9) / 2
            then = then_problem(self, washer_diameter_mm=need)
            raise HolderError(f"the retention washers (washer_diameter_mm {self.washer_diameter_mm:g}) overlap the "
                              f"die edge by {overlap:.2f} mm (< 0.5 mm): set washer_diameter_mm = {need:g} or more"
                              + (f" (then: {then})" if then else ""))
        problem = recess_chamfer_problem(self)
        if problem:
            raise HolderError(problem)
        if self.cartridge_need_mm > self.cartridge_radius_mm + 1e-9:
            raise HolderError(die_too_large_problem(self))

    def _check_flare(self) -> None:
        """The hole in front of the DOE, flared toward the scene at ``field_half_angle_deg``, leaves wall_mm of the
        cartridge around it (its body, the die's retention screws and, in its flange, the lock-screw slots)."""
        if self._flare_fits(self.field_half_angle_deg):
            return
        fits = (a / 10 for a in range(int(10 * self.field_half_angle_deg), -1, -1))
        widest = next((a for a in fits if self._flare_fits(a)), 0.0)
        raise HolderError(f"field_half_angle_deg ({self.field_half_angle_deg:g}°): the hole in front of the DOE, "
                          f"flared at that angle over {self.aperture_depth_mm:.2f} mm, reaches a radius of "
                          f"{self.aperture_flare_radius_mm:.2f} mm and comes within "
                          f"{self._flare_to_screws_mm(self.field_half_angle_deg):.2f} mm of the die's retention "
                          f"screws, leaving the cartridge less than wall_mm ({self.wall_mm:g} mm) round it: set "
                          f"field_half_angle_deg = {widest:g} or less (a wider field's corners are vignetted by the "
                          f"holder), or use a larger thread or die")

    def _flare_fits(self, angle_deg: float) -> bool:
        """Whether a hole flared at ``angle_deg`` leaves wall_mm round it: to the cartridge's side and its flange's
        lock-screw slots, and to the die's retention screws."""
        room = min(self.cartridge_radius_mm, self.pilot_radius_mm - self.screw_clearance_mm / 2) - self.wall_mm
        return (self._hole_radius(angle_deg, self.aperture_depth_mm) <= room + 1e-9
                and self._flare_to_screws_mm(angle_deg) >= self.wall_mm - 1e-9)

    def _check_flange_diameter(self) -> None:
        problem = flange_diameter_problem(self)
        if problem:
            raise HolderError(problem)

    def _check_flange_height(self) -> None:
        problem = flange_height_problem(self)
        if problem:
            raise HolderError(problem)

    # ---- derived dimensions (mm) --------------------------------------------------------------
    @property
    def thread_major_radius_mm(self) -> float:
        """Outer radius of the printed male thread (mm), half the nominal diameter less ``thread_clearance_mm``."""
        return self.thread_diameter_mm / 2 - self.thread_clearance_mm

    @property
    def thread_engagement_mm(self) -> float:
        """How far (mm, radially) the printed thread reaches into the lens's female thread: its outer radius less
        the female thread's minor radius, (D − 1.0825·P) / 2 (ISO basic profile): 0.541·P − thread_clearance_mm."""
        return self.thread_major_radius_mm - (self.thread_diameter_mm - 2 * derive.ISO_DEPTH * self.thread_pitch_mm) / 2

    @property
    def seat_radius_mm(self) -> float:
        """Radius (mm) of the flange's 45° chamfer at the thread's end, the plane of the lens's filter face: the
        female thread's minor radius, (D − 1.0825·P) / 2, where the chamfer meets the mouth's crest — so the base
        seats there, not a tooth's engagement short of it (at most the printed thread's outer radius)."""
        minor = (self.thread_diameter_mm - 2 * derive.ISO_DEPTH * self.thread_pitch_mm) / 2
        return min(self.thread_major_radius_mm, minor)

    @property
    def thread_root_radius_mm(self) -> float:
        """Root radius of the printed thread (mm), the major radius less ``thread_depth_mm``."""
        return self.thread_major_radius_mm - self.thread_depth_mm

    @property
    def bore_radius_mm(self) -> float:
        """Radius of the base's cylindrical bore (the cartridge seat)."""
        if self.mount == "thread":
            return self.thread_root_radius_mm - self.wall_mm
        return self.barrel_diameter_mm / 2 - self.wall_mm - 3.0  # the top plate's opening

    @property
    def cartridge_radius_mm(self) -> float:
        """Outer radius of the cartridge body (mm), the bore radius less ``clearance_mm``."""
        return self.bore_radius_mm - self.clearance_mm

    @property
    def die_diagonal_mm(self) -> float:
        """Diagonal of the die (mm), which the cartridge's die pocket must hold."""
        return math.hypot(self.die_width_mm, self.die_height_mm)

    @property
    def washer_recess_half_mm(self) -> float:
        """Half-width (mm) of each washer's square-cornered recess: the washer's radius plus ``clearance_mm``."""
        return self.washer_diameter_mm / 2 + self.clearance_mm

    @property
    def warnings(self) -> list[str]:
        """What is unusual but allowed (``derive.thread_warnings``: a thread size or pitch no filter has)."""
        return derive.thread_warnings(self.thread_diameter_mm, self.thread_pitch_mm) if self.mount == "thread" else []

    @property
    def pocket_corner_radius_mm(self) -> float:
        """The die pocket's farthest point from the axis (mm): a square corner of the die outline offset by
        ``clearance_mm`` with mitred corners (``recipe.offset_convex``), (w/2 + c, h/2 + c) — √2·c beyond the die's
        corner, not c (the coded half's chamfered corners lie nearer)."""
        c = self.clearance_mm
        return math.hypot(self.die_width_mm / 2 + c, self.die_height_mm / 2 + c)

    @property
    def cartridge_need_mm(self) -> float:
        """The cartridge radius (mm) that holds the die pocket and the washer recesses with wall_mm around them
        (a recess runs from the pocket to ``washer_recess_half_mm`` beyond its screw)."""
        rw = self.washer_recess_half_mm
        return max(self.pocket_corner_radius_mm, math.hypot(self.screw_offset_mm + rw, rw)) + self.wall_mm

    @property
    def cartridge_length_mm(self) -> float:
        """The cartridge's body below its flange (mm): it reaches the base's lens-side end (the thread's tip, or the
        slip-fit plate's face)."""
        return self.base_height_mm if self.mount == "thread" else self.flange_height_mm

    @property
    def aperture_depth_mm(self) -> float:
        """How far the hole in front of the DOE reaches (mm): from the cartridge's scene-side face to the die."""
        return self.cartridge_flange_mm + self.cartridge_length_mm - self.washer_recess_mm - self.die_thickness_mm

    @property
    def seat_margin_mm(self) -> float:
        """How much wider than the clear aperture the hole is where the die rests on it (mm, radius;
        :func:`holder_cad.derive.seat_margin_mm`)."""
        return derive.seat_margin_mm(self.aperture_margin_mm, self.die_thickness_mm, self.field_half_angle_deg,
                                     self.wall_mm)

    @property
    def flare_step_mm(self) -> float:
        """How far below the die the hole stays straight before it flares (mm): ``wall_mm`` (0 without a flare)."""
        return self._flare_step(self.field_half_angle_deg)

    @property
    def aperture_flare_radius_mm(self) -> float:
        """The hole's radius at the cartridge's scene-side face (mm): the clear aperture's plus ``seat_margin_mm``
        at the die, widening at ``field_half_angle_deg`` toward the scene below a ``flare_step_mm`` straight step."""
        return self._hole_radius(self.field_half_angle_deg, self.aperture_depth_mm)

    def _flare_step(self, angle_deg: float) -> float:
        return self.wall_mm if angle_deg > 0 else 0.0

    def _hole_radius(self, angle_deg: float, below_die_mm: float) -> float:
        """The radius (mm) of a hole flared at ``angle_deg``, ``below_die_mm`` in front of the die's back face."""
        margin = derive.seat_margin_mm(self.aperture_margin_mm, self.die_thickness_mm, angle_deg, self.wall_mm)
        return (self.clear_aperture_mm / 2 + margin
                + max(below_die_mm - self._flare_step(angle_deg), 0.0) * math.tan(math.radians(angle_deg)))

    def _flare_to_screws_mm(self, angle_deg: float) -> float:
        """The material (mm) between a hole flared at ``angle_deg`` and the bottom of the retention screws' pilot
        holes, square to the flare."""
        seat_to_hole = derive.RETENTION_DEPTH_MM - self.die_thickness_mm  # the holes' bottom below the die's back
        r_at_hole = self._hole_radius(angle_deg, seat_to_hole)
        return (self.screw_offset_mm - self.pilot_hole_mm / 2 - r_at_hole) * math.cos(math.radians(angle_deg))

    @property
    def chamfer_height_mm(self) -> float:
        """Height of the flange's 45° chamfer (mm) above the thread's end, from its seat radius to the flange's
        outer radius."""
        return self.flange_diameter_mm / 2 - self.seat_radius_mm

    @property
    def base_height_mm(self) -> float:
        """Height of the base ring (mm), thread (or sleeve) length plus flange height."""
        if self.mount == "thread":
            return self.thread_length_mm + self.flange_height_mm
        return self.sleeve_length_mm + self.flange_height_mm

    @property
    def doe_to_lens_mm(self) -> float:
        """Distance from the DOE's patterned face to the lens glass vertex.

        The DOE face sits ``washer_recess_mm`` inside the cartridge's lens-side end, which is flush with the
        base's lens-side end (the thread's tip, or the plate's face against the barrel).
        """
        return self.glass_gap_mm + self.washer_recess_mm

    @property
    def glass_gap_mm(self) -> float:
        """From the cartridge's lens-side end (flush with the thread's tip, or the plate's face) to the lens glass
        vertex (mm)."""
        reach = self.thread_length_mm if self.mount == "thread" else 0.0
        return self.lens_face_to_glass_mm - reach

    @property
    def screw_offset_mm(self) -> float:
        """x of the two die-retention screws (mm), with wall_mm of plastic between pocket and pilot hole."""
        return self.die_width_mm / 2 + self.clearance_mm + self.wall_mm + self.pilot_hole_mm / 2

    @property
    def sleeve_outer_radius_mm(self) -> float:
        """Outer radius of the slip-fit sleeve (mm), barrel radius plus clearance and wall."""
        return self.barrel_diameter_mm / 2 + self.clearance_mm + self.wall_mm

    @property
    def pilot_radius_mm(self) -> float:
        """Radius of the lock-screw circle (mm), mid-flange (thread) or outside the sleeve, clear of the barrel (slip)."""
        if self.mount == "thread":
            return 0.5 * (self.bore_radius_mm + self.flange_diameter_mm / 2)
        return self.sleeve_outer_radius_mm + self.wall_mm + self.pilot_hole_mm / 2

    @property
    def pilot_stop_mm(self) -> float:
        """Height (mm) above the thread's end at which the base's blind pilot holes stop: wall_mm, square to the
        45° chamfer, short of it (threaded base); the slip-fit plate is drilled through (its bottom)."""
        if self.mount == "thread":
            return (self.pilot_radius_mm + self.pilot_hole_mm / 2 + self.wall_mm * math.sqrt(2)
                    - self.seat_radius_mm)
        return 0.0

    def replace(self, **changes) -> "HolderParams":
        """A copy with some parameters changed (millimetres), checked again; parameters that were derived are
        derived again (a new thread gets its own pitch and flange), ``None`` derives a given one."""
        given = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in self._derived}
        return HolderParams(**{**given, **changes})

    def to_dict(self) -> dict:
        """Every parameter by name (lengths in millimetres), as ``holder.json`` stores them."""
        return dataclasses.asdict(self)
