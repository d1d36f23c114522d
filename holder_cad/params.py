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

__all__ = ["HolderParams", "HolderError", "fit_bounds", "PARAM_RANGES"]


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


@dataclass(frozen=True)
class HolderParams:
    """All dimensions in millimetres.

    Attributes:
        mount: ``"thread"`` (male filter thread into the lens) or ``"slip"`` (sleeve over the front barrel).
        thread_diameter_mm: nominal filter thread diameter (49 for the Canon EF 50 mm f/1.8 STM).
        thread_pitch_mm: thread pitch (0.75).  thread_depth_mm: tooth height (0.3; 45° flanks).
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
        flange_diameter_mm: outer diameter of both flanges.  flange_height_mm, cartridge_flange_mm: heights.
        screw_clearance_mm, pilot_hole_mm: M2 clearance hole and pilot (self-tapping) hole diameters.
        washer_diameter_mm, washer_recess_mm: retention washers (recessed so nothing protrudes to the lens).
        max_doe_to_lens_mm: the farthest the DOE may sit in front of the lens glass (the split-aperture optics
            assume it close to the aperture; 5 mm keeps the PSF change small, see the tolerance study).
        segments: facets of a full circle (mesh path).

    Every derived quantity that decides the fit has a bound (:func:`fit_bounds`); a parameter set that
    violates one is refused before anything is built, with the quantity, its value and the limit.
    """

    mount: str = "thread"
    thread_diameter_mm: float = 49.0
    thread_pitch_mm: float = 0.75
    thread_depth_mm: float = 0.3
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
    flange_diameter_mm: float = 57.0
    flange_height_mm: float = 6.0
    cartridge_flange_mm: float = 2.4
    screw_clearance_mm: float = 2.4
    pilot_hole_mm: float = 1.7
    washer_diameter_mm: float = 6.0
    washer_recess_mm: float = 0.6
    max_doe_to_lens_mm: float = 5.0
    segments: int = 128

    def __post_init__(self) -> None:
        errs = []
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name.endswith("_mm") and (not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0):
                errs.append(f"{f.name} must be a positive length in mm, got {v!r}")
        if errs:
            raise HolderError("; ".join(errs))
        out = [f"{k} {getattr(self, k):g} is outside {lo:g}–{hi:g} mm ({why})" for k, (lo, hi, why) in
               PARAM_RANGES.items() if not lo <= getattr(self, k) <= hi]
        if out:
            raise HolderError("; ".join(out))
        if self.mount not in ("thread", "slip"):
            raise HolderError(f"mount must be 'thread' or 'slip', got {self.mount!r}")
        if self.wall_mm < self.nozzle_mm:
            raise HolderError(f"wall_mm ({self.wall_mm}) is below nozzle_mm ({self.nozzle_mm}): a printer cannot "
                              f"make walls thinner than one line; raise wall_mm")
        if self.clear_aperture_mm + 2 * self.aperture_margin_mm >= min(self.die_width_mm, self.die_height_mm) - 2 * self.wall_mm:
            raise HolderError(f"clear_aperture_mm ({self.clear_aperture_mm}) + margins does not fit inside the die "
                              f"({self.die_width_mm} × {self.die_height_mm} mm) with a {self.wall_mm} mm ledge: use "
                              f"a larger die or a smaller aperture")
        if self.die_chamfer_mm >= 0.5 * min(self.die_width_mm, self.die_height_mm):
            raise HolderError("die_chamfer_mm must be less than half the die side")
        if self.thread_depth_mm * 2 >= self.thread_pitch_mm:
            raise HolderError(f"thread_depth_mm ({self.thread_depth_mm}) is too deep for thread_pitch_mm "
                              f"({self.thread_pitch_mm}) with 45° flanks: depth must be < pitch / 2")
        overlap = self.die_width_mm / 2 - (self.screw_offset_mm - self.washer_diameter_mm / 2)
        if overlap < 0.5:
            raise HolderError(f"the retention washers (washer_diameter_mm {self.washer_diameter_mm}) overlap the die "
                              f"edge by {overlap:.2f} mm (< 0.5 mm): use larger washers")
        if not isinstance(self.segments, int) or not 32 <= self.segments <= 1024:
            raise HolderError(f"segments must be an integer in 32..1024 (facets per circle), got {self.segments!r}")
        # the cartridge body must hold the die pocket with walls around it
        if self.die_diagonal_mm / 2 + self.clearance_mm + self.wall_mm > self.cartridge_radius_mm:
            raise HolderError(f"the die ({self.die_width_mm} × {self.die_height_mm} mm) does not fit the cartridge "
                              f"(radius {self.cartridge_radius_mm:.2f} mm) with clearance_mm and wall_mm: use a "
                              f"larger thread/barrel or a smaller die")
        rf = self.flange_diameter_mm / 2
        if self.pilot_radius_mm + self.screw_clearance_mm / 2 + self.wall_mm > rf + 1e-9 or (
                self.pilot_radius_mm - self.pilot_hole_mm / 2 - self.wall_mm < self.bore_radius_mm - 1e-9):
            need = 2 * (self.pilot_radius_mm + self.screw_clearance_mm / 2 + self.wall_mm)
            raise HolderError(f"flange_diameter_mm ({self.flange_diameter_mm}) leaves no room for the lock-screw "
                              f"holes and slots with wall_mm around them: use at least {need:.1f} mm")
        if self.mount == "slip" and rf < self.sleeve_outer_radius_mm + self.wall_mm:
            raise HolderError(f"flange_diameter_mm ({self.flange_diameter_mm}) must cover the sleeve (outer "
                              f"diameter {2 * self.sleeve_outer_radius_mm:.2f} mm from barrel_diameter_mm)")
        if self.mount == "thread" and self.flange_diameter_mm / 2 <= self.thread_major_radius_mm + self.wall_mm:
            raise HolderError("flange_diameter_mm must exceed the thread diameter by 2 × wall_mm")
        if self.mount == "thread" and self.chamfer_height_mm + self.wall_mm > self.flange_height_mm:
            raise HolderError(f"flange_height_mm ({self.flange_height_mm}) is too low for the 45° chamfer "
                              f"({self.chamfer_height_mm:.2f} mm) plus wall_mm")
        bad = [b for b in fit_bounds(self) if not b["ok"]]
        if bad:
            raise HolderError("; ".join(f"{b['quantity']} = {b['value']:.3g} {b['unit']} is outside "
                                        f"{b['min']:g}–{b['max']:g} {b['unit']} ({b['fix']})" for b in bad))

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

    def replace(self, **changes) -> "HolderParams":
        """A copy with some parameters changed (millimetres), checked again."""
        return dataclasses.replace(self, **changes)

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
