"""Holder parameters. Units: millimetres (the CAD convention) — every length field ends in ``_mm``.

The part is two bodies printed separately, each flat on the bed and support-free:
- the **base ring**: a male filter thread (default M49 × 0.75, 45° flanks so every overhang is ≤ 45°) or a
  slip-fit sleeve, a 45°-chamfered flange, a cylindrical bore for the cartridge, four M2 pilot holes and
  10° graduation notches on its rim;
- the **cartridge**: a flange that rests on the base and a body that reaches down the bore to the lens side,
  holding the fused-silica die in a keyed pocket (one chamfered die corner: the die fits one way only, not
  rotated, not flipped), with a clear aperture, two M2 retention screws whose washers overlap the die edge,
  two 100° arc slots centred on ±x (any rotation can be locked on the base's pilot holes: the thread's
  start angle does not matter) and two index notches at ±y, on the split-line direction.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from holder_cad import derive

__all__ = ["HolderParams", "HolderError", "fit_bounds", "PARAM_RANGES", "given_problem"]


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
    "thread_length_mm": (0.5, 30.0, "the engaged thread length"),
    "barrel_diameter_mm": (20.0, 150.0, "a lens front barrel"),
    "sleeve_length_mm": (1.0, 100.0, "the slip-fit sleeve"),
    "lens_face_to_glass_mm": (0.01, 50.0, "filter face to front glass: measure your lens"),
    "die_width_mm": (2.0, 100.0, "the fused-silica die"),
    "die_height_mm": (2.0, 100.0, "the fused-silica die"),
    "die_thickness_mm": (0.1, 10.0, "the fused-silica die"),
    "die_chamfer_mm": (0.1, 50.0, "the keyed die corner"),
    "clear_aperture_mm": (0.5, 100.0, "the DOE clear aperture"),
    "aperture_margin_mm": (0.01, 10.0, "extra radius of the hole"),
    "clearance_mm": (0.05, 1.0, "below 0.05 mm a printed pocket will not take the die, above 1 mm the die rattles"),
    "wall_mm": (0.1, 10.0, "between one nozzle line and 10 mm"),
    "nozzle_mm": (0.1, 2.0, "a printer nozzle"),
    "flange_diameter_mm": (20.0, 250.0, "fits a printer bed"),
    "flange_height_mm": (0.5, 50.0, "the base flange"),
    "cartridge_flange_mm": (0.5, 50.0, "the cartridge flange"),
    "screw_clearance_mm": (0.5, 10.0, "an M2 clearance hole is 2.4 mm"),
    "pilot_hole_mm": (0.3, 10.0, "an M2 pilot hole is 1.7 mm"),
    "washer_diameter_mm": (1.0, 30.0, "an M2 washer is 5–6 mm"),
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
    seg = values.get("segments", 128)
    if isinstance(seg, bool) or not isinstance(seg, int) or not 32 <= seg <= 1024:
        return f"segments must be an integer in 32..1024 (facets per circle), got {seg!r}"
    return None


@dataclass(frozen=True)
class HolderParams:
    """All dimensions in millimetres.

    Attributes:
        mount: ``"thread"`` (male filter thread into the lens) or ``"slip"`` (sleeve over the front barrel).
        thread_diameter_mm: nominal filter thread diameter (49 for the Canon EF 50 mm f/1.8 STM).
        thread_pitch_mm: thread pitch (by default the commonest for the diameter: 0.75 for 49 mm).
        thread_depth_mm: tooth height (by default 0.4 × pitch; 45° flanks).
        thread_length_mm: engaged thread length (2.5).
        barrel_diameter_mm: outer diameter of the lens front barrel (slip fit only).
        sleeve_length_mm: slip-fit sleeve length.
        lens_face_to_glass_mm: from the lens's filter face (or barrel front) to the front glass vertex; the
            DOE-to-lens distance follows from it (measure your lens; 3.5 is an estimate for the EF 50/1.8 STM).
        die_width_mm, die_height_mm, die_thickness_mm: the fused-silica die (12 × 12 × 1 fits the 8.64 mm
            aperture and the mask set's marks).  die_chamfer_mm: the keyed die corner (top-left, coded side).
        clear_aperture_mm: DOE clear aperture (8.64).  aperture_margin_mm: extra radius of the hole.
        clearance_mm: fit clearance per side (die in pocket, cartridge in bore, thread).
        wall_mm: minimum wall (≥ the nozzle width).  nozzle_mm: printer nozzle width.
        flange_diameter_mm: outer diameter of both flanges (by default the least that holds the lock screws).
        flange_height_mm: the base flange (by default the least over the chamfer and the pilot holes).
        cartridge_flange_mm: the cartridge flange's height.
        screw_clearance_mm, pilot_hole_mm: M2 clearance hole and pilot (self-tapping) hole diameters.
        washer_diameter_mm, washer_recess_mm: retention washers (recessed so nothing protrudes to the lens).
        max_doe_to_lens_mm: the farthest the DOE may sit in front of the lens glass (the split-aperture optics
            assume it close to the aperture; 5 mm keeps the PSF change small, see the tolerance study).
        segments: facets of a full circle (mesh path).

    The four parameters of :data:`holder_cad.derive.DERIVED` default to ``None``: they then follow from the
    thread (or barrel) and the die by the rules of :mod:`holder_cad.derive`, and :attr:`derived` names them.
    Every derived quantity that decides the fit has a bound (:func:`fit_bounds`); a parameter that violates
    one is refused before anything is built, with the parameter to change and a value that works.
    """

    mount: str = "thread"
    thread_diameter_mm: float = 49.0
    thread_pitch_mm: float | None = None
    thread_depth_mm: float | None = None
    thread_length_mm: float = 2.5
    barrel_diameter_mm: float = 56.0
    sleeve_length_mm: float = 8.0
    lens_face_to_glass_mm: float = 3.5
    die_width_mm: float = 12.0
    die_height_mm: float = 12.0
    die_thickness_mm: float = 1.0
    die_chamfer_mm: float = 1.5
    clear_aperture_mm: float = 8.64
    aperture_margin_mm: float = 0.3
    clearance_mm: float = 0.25
    wall_mm: float = 1.2
    nozzle_mm: float = 0.4
    flange_diameter_mm: float | None = None
    flange_height_mm: float | None = None
    cartridge_flange_mm: float = 2.4
    screw_clearance_mm: float = 2.4
    pilot_hole_mm: float = 1.7
    washer_diameter_mm: float = 6.0
    washer_recess_mm: float = 0.6
    max_doe_to_lens_mm: float = 5.0
    segments: int = 128

    def __post_init__(self) -> None:
        object.__setattr__(self, "_derived", tuple(n for n in derive.DERIVED if getattr(self, n) is None))
        self._check_given()
        self._resolve("thread_pitch_mm", derive.standard_pitch_mm(self.thread_diameter_mm))
        self._resolve("thread_depth_mm", derive.standard_depth_mm(self.thread_pitch_mm))
        self._check_die_and_thread()
        self._resolve("flange_diameter_mm", derive.flange_diameter_mm(self))
        self._check_flange_diameter()
        self._resolve("flange_height_mm", derive.flange_height_mm(self))
        self._check_flange_height()
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
        ledge = derive.widest_aperture_mm(side, self.wall_mm, self.aperture_margin_mm)
        if self.clear_aperture_mm >= ledge:
            raise HolderError(f"clear_aperture_mm ({self.clear_aperture_mm:g}) + margins does not fit inside the "
                              f"die ({self.die_width_mm:g} × {self.die_height_mm:g} mm) with a {self.wall_mm:g} mm "
                              f"ledge: set clear_aperture_mm = {math.floor(100 * ledge - 1) / 100:g} or less, or "
                              f"die_width_mm and die_height_mm to "
                              f"{math.ceil(self.clear_aperture_mm + side - ledge + 0.01):g} or more")
        if self.die_chamfer_mm >= 0.5 * side:
            raise HolderError(f"die_chamfer_mm ({self.die_chamfer_mm:g}) must be less than half the die's shorter "
                              f"side ({side:g} mm): set die_chamfer_mm = {min(1.5, side / 4):g}")
        if self.thread_depth_mm * 2 >= self.thread_pitch_mm:
            raise HolderError(f"thread_depth_mm ({self.thread_depth_mm:g}) is too deep for thread_pitch_mm "
                              f"({self.thread_pitch_mm:g}) with 45° flanks (depth < pitch / 2): set "
                              f"thread_depth_mm = {derive.standard_depth_mm(self.thread_pitch_mm):g}")
        overlap = self.die_width_mm / 2 - (self.screw_offset_mm - self.washer_diameter_mm / 2)
        if overlap < 0.5:
            need = math.ceil(2 * (self.washer_diameter_mm / 2 + 0.5 - overlap) * 2 - 1e-9) / 2
            raise HolderError(f"the retention washers (washer_diameter_mm {self.washer_diameter_mm:g}) overlap the "
                              f"die edge by {overlap:.2f} mm (< 0.5 mm): set washer_diameter_mm = {need:g} or more")
        if self.cartridge_need_mm > self.cartridge_radius_mm + 1e-9:
            raise HolderError(self._die_too_large())

    def _die_too_large(self) -> str:
        """The refusal of a die the cartridge cannot hold, with a thread (or barrel) and a die that work."""
        c, wall, rw, need = self.clearance_mm, self.wall_mm, self.washer_recess_half_mm, self.cartridge_need_mm
        # the largest square die whose pocket and washer recesses fit this cartridge
        reach = self.screw_offset_mm - self.die_width_mm / 2  # pocket edge to screw axis
        room = self.cartridge_radius_mm - wall
        half = min((room - c) / math.sqrt(2), math.sqrt(max(room ** 2 - rw ** 2, 0.0)) - reach - rw)
        side = math.floor(20 * half) / 10
        holds = side - 2 * wall - 2 * self.aperture_margin_mm > self.clear_aperture_mm  # it still takes the DOE
        die = f", or use a die of at most {side:g} × {side:g} mm (die_width_mm, die_height_mm)" if holds else ""
        what = (f"the die ({self.die_width_mm:g} × {self.die_height_mm:g} mm), its pocket and the washer recesses "
                f"need a cartridge of radius {need:.2f} mm, this one has {self.cartridge_radius_mm:.2f} mm")
        if self.mount == "slip":
            barrel = math.ceil(2 * (need + c + wall + 3.0) * 2 - 1e-9) / 2
            return f"{what}: set barrel_diameter_mm = {barrel:g} or more{die}"
        thread = 2 * (need + 2 * c + wall + self.thread_depth_mm)
        if "thread_depth_mm" in self._derived and "thread_pitch_mm" in self._derived:  # a larger thread's teeth
            thread = 2 * (need + 2 * c + wall + derive.standard_depth_mm(derive.standard_pitch_mm(thread)))
        thread = derive.next_filter_thread_mm(thread)
        return (f"{what}: set thread_diameter_mm = {thread:g} or more (a step-up ring from the lens's "
                f"{self.thread_diameter_mm:g} mm thread){die}")

    def _check_flange_diameter(self) -> None:
        least = derive.min_flange_diameter_mm(self)
        if self.flange_diameter_mm < least - 1e-9:
            what = (f"the {self.thread_diameter_mm:g} mm thread's bore" if self.mount == "thread" else
                    f"the sleeve over the {self.barrel_diameter_mm:g} mm barrel")
            src = "thread" if self.mount == "thread" else "barrel"
            raise HolderError(f"flange_diameter_mm ({self.flange_diameter_mm:g}) is below {least:.2f} mm, the least "
                              f"that holds {what} and the lock-screw holes and slots with wall_mm "
                              f"({self.wall_mm:g} mm) on both sides: set flange_diameter_mm = "
                              f"{derive.flange_diameter_mm(self):g}, or leave it out (it follows from the {src})")

    def _check_flange_height(self) -> None:
        hi = PARAM_RANGES["flange_height_mm"][1]
        if "flange_height_mm" in self._derived and self.flange_height_mm > hi:
            raise HolderError(f"flange_diameter_mm ({self.flange_diameter_mm:g}) needs a "
                              f"{self.flange_height_mm:g} mm flange height over its 45° chamfer, above the "
                              f"{hi:g} mm allowed: set flange_diameter_mm = "
                              f"{derive.max_flange_diameter_mm(self, hi):g} or less, or leave it out")
        need = derive.min_flange_height_mm(self)
        if self.flange_height_mm < need - 1e-9:
            why = (f"the 45° chamfer ({self.chamfer_height_mm:.2f} mm) plus wall_mm and lock-screw pilot holes "
                   f"{derive.PILOT_DEPTH_MM:g} mm deep above it" if self.mount == "thread" else
                   f"lock-screw pilot holes {derive.PILOT_DEPTH_MM:g} mm deep")
            raise HolderError(f"flange_height_mm ({self.flange_height_mm:g}) is too low: {why} need {need:.2f} mm: "
                              f"set flange_height_mm = {derive.flange_height_mm(self):g}, or leave it out (it "
                              f"follows from the flange)")

    # ---- derived dimensions (mm) --------------------------------------------------------------
    @property
    def thread_major_radius_mm(self) -> float:
        """Outer radius of the printed male thread (mm), half the nominal diameter less ``clearance_mm``."""
        return self.thread_diameter_mm / 2 - self.clearance_mm

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
    def cartridge_need_mm(self) -> float:
        """The cartridge radius (mm) that holds the die pocket and the washer recesses with wall_mm around them
        (a recess runs from the pocket to ``washer_recess_half_mm`` beyond its screw)."""
        rw = self.washer_recess_half_mm
        return max(self.die_diagonal_mm / 2 + self.clearance_mm, math.hypot(self.screw_offset_mm + rw, rw)) + self.wall_mm

    @property
    def chamfer_height_mm(self) -> float:
        """Height of the flange's 45° chamfer (mm), from the thread to the flange's outer radius."""
        return self.flange_diameter_mm / 2 - self.thread_major_radius_mm

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
        reach = self.thread_length_mm if self.mount == "thread" else 0.0
        return self.lens_face_to_glass_mm - reach + self.washer_recess_mm

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
                    - self.thread_major_radius_mm)
        return 0.0

    def replace(self, **changes) -> "HolderParams":
        """A copy with some parameters changed (millimetres), checked again; parameters that were derived are
        derived again (a new thread gets its own pitch and flange), ``None`` derives a given one."""
        given = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in self._derived}
        return HolderParams(**{**given, **changes})

    def to_dict(self) -> dict:
        """Every parameter by name (lengths in millimetres), as ``holder.json`` stores them."""
        return dataclasses.asdict(self)


def _param_row(p: HolderParams, name: str) -> tuple:
    lo, hi, why = PARAM_RANGES[name]
    return name, getattr(p, name), lo, hi, "mm", why


def fit_bounds(p: HolderParams, doe_to_lens_mm: float | None = None) -> list[dict]:
    """Bounds on the derived quantities that decide whether the holder fits and works (millimetres).

    ``doe_to_lens_mm``: a measured value (from the built mesh) instead of the formula's. Each entry:
    quantity, value, min, max, unit, ok, fix.
    """
    d = p.doe_to_lens_mm if doe_to_lens_mm is None else doe_to_lens_mm
    cart_len = p.base_height_mm if p.mount == "thread" else p.flange_height_mm
    rows = [
        ("doe_to_lens_mm", d, 0.2, p.max_doe_to_lens_mm, "mm",
         "the DOE must sit close to, but clear of, the lens glass: check thread_length_mm, washer_recess_mm and "
         "lens_face_to_glass_mm"),
        ("die_to_pocket_clearance_mm", p.clearance_mm, *PARAM_RANGES["clearance_mm"][:2], "mm",
         "clearance_mm: " + PARAM_RANGES["clearance_mm"][2]),
        ("washer_recess_mm", p.washer_recess_mm, p.nozzle_mm / 2, PARAM_RANGES["washer_recess_mm"][1], "mm",
         PARAM_RANGES["washer_recess_mm"][2]),
        ("die_seat_thickness_mm", p.cartridge_flange_mm + cart_len - p.washer_recess_mm - p.die_thickness_mm,
         p.wall_mm, 1e3, "mm", "material under the die pocket must be at least wall_mm: a smaller "
                               "washer_recess_mm or die_thickness_mm, or a longer thread/flange"),
        ("wall_mm", p.wall_mm, p.nozzle_mm, 10.0, "mm", "wall_mm between one nozzle line and 10 mm"),
    ]
    if p.mount == "thread":
        rows += [
            _param_row(p, "thread_pitch_mm"),
            ("thread_engagement_turns", p.thread_length_mm / p.thread_pitch_mm, 2.0, 20.0, "turns",
             "thread_length_mm must give 2–20 turns of thread_pitch_mm"),
            _param_row(p, "thread_depth_mm"),
        ]
    return [{"quantity": q, "value": float(v), "min": lo, "max": hi, "unit": u, "ok": bool(lo <= v <= hi), "fix": fix}
            for q, v, lo, hi, u, fix in rows]
