"""The kinds of error a tolerance study knows, in one table: unit, sweep, the part with that error alone, the
budget's standard deviation of it, and whether its simulation depends on the grid (and so enters the grid study).

``grid = False`` for errors that are exact on any grid: an etch depth scales the heights, a decenter moves the
split line and the lens (``mounted``), a gap is propagated analytically or not at all, crosstalk mixes views.
Mask-level errors cut cells into slivers (exact areas, flat-tile far field) and a mount rotation turns the
relief (band-limited interpolation): their error against finer grids is measured per design (``grid``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable

from doefab.tolerance.errors import PartErrors
from doefab.tolerance.sources import budget_value, etch_sigma, nominal_gap, sensor_errors

__all__ = ["Kind", "KINDS", "kind", "budget_part"]


def _overlay(v: float, n_masks: int) -> PartErrors:
    """Every plate off by v (the length of its 2-D shift) relative to the one it aligns to, in the four diagonal
    directions in turn."""
    s = v / math.sqrt(2)
    turns = ((s, s), (-s, s), (-s, -s), (s, -s))
    return replace(PartErrors(), overlay=tuple(turns[m % 4] for m in range(n_masks)))


def _mask_rotation(v: float, n_masks: int) -> PartErrors:
    """Every plate turned by v relative to the one it aligns to, alternately one way and the other."""
    return replace(PartErrors(), rotation=tuple(v if m % 2 == 0 else -v for m in range(n_masks)))


@dataclass(frozen=True)
class Kind:
    """One error kind. ``build(v, n_masks)``: the part with only this error, of magnitude v (SI), for a design of
    ``n_masks`` masks; ``from_budget``: one standard deviation of what ``errors.sample_errors`` draws of it (SI;
    a uniform decenter ±d: d/√3 per axis; the etch depth: the systematic and random parts added in quadrature, one
    plate's spread, put on every plate alike;
    a plate's 2-D overlay shift: the rms of its length, √2 × the per-axis sigma), so every kind is judged at the
    same probability point and the ranking compares like with like; an error every part carries alike (corner
    rounding, roughness, crosstalk, the holder's nominal axial gap) at that value; 0 when the budget has none of
    it. ``base_from_budget``: the part a deviation is measured from where the draws do not centre on the
    error-free part (the axial gap's spread about its nominal value); None: the error-free part. ``remedy``: what
    would remove it (the report's "would buy the most")."""

    name: str
    source: str  # the source of error (``sources.SOURCES``) whose budget keys and draws it judges
    unit: str
    si: float  # SI units per ``unit``
    sweep: tuple
    build: Callable[[float, int], PartErrors]
    from_budget: Callable[[dict], float]
    grid: bool
    part_from_budget: Callable[[dict], PartErrors] | None = None
    base_from_budget: Callable[[dict], PartErrors] | None = None
    remedy: str = ""  # what would remove it, for the report's "would buy the most"

    def budget_part(self, budget: dict, n_masks: int) -> PartErrors:
        """The part with one standard deviation of this error alone, for a design of ``n_masks`` masks."""
        if self.part_from_budget is not None:
            return self.part_from_budget(budget)
        return self.build(self.from_budget(budget), n_masks)

    def base_part(self, budget: dict) -> PartErrors:
        """The part this kind's change is measured from: the error-free part, or the draws' centre."""
        return PartErrors() if self.base_from_budget is None else self.base_from_budget(budget)


def _crosstalk(calibrated: bool):
    def build(v, n_masks):
        return replace(PartErrors(), crosstalk=(v, v), calibrated=calibrated)
    return build


def _gap_sigma(budget) -> float:
    """One standard deviation (m) of the axial gap about the holder's nominal gap."""
    return budget_value(budget, "mounting", "axial_gap_sigma_mm") * 1e-3


def _gap_part(offset):
    """The part whose axial gap is the nominal gap plus ``offset(budget)`` (m)."""
    return lambda b: replace(PartErrors(), axial_gap=nominal_gap(b) + offset(b))


def _decenter_sigma(budget) -> float:
    """One standard deviation (m) of the decenter, uniform in ±decenter_max_mm on each axis."""
    return budget_value(budget, "mounting", "decenter_max_mm") * 1e-3 / math.sqrt(3)


def _crosstalk_part(calibrated: bool):
    """The budget's sensor (ratios, their slope across the sensor, its calibration), calibrated or not."""
    def part(b):
        return replace(PartErrors(), **{**sensor_errors(b), "calibrated": calibrated})
    return part


def _crosstalk_value(calibrated: bool):
    """The budget's crosstalk for the kind of its camera (calibrated or not); 0 for the other kind: a budget
    judges the pipeline it describes, not the one it does not."""
    def value(b) -> float:
        s = sensor_errors(b)
        return max(s["crosstalk"]) if s["calibrated"] == calibrated else 0.0
    return value


KINDS = (
    Kind("etch depth (all plates alike)", "etch depth", "%", 0.01, (-10, -5, -2, 2, 5, 10),
         lambda v, n: replace(PartErrors(), depth_scale=(1 + v,) * n),
         etch_sigma,
         False,
         remedy="tighter etch-depth control (monitor wafers, an etch-stop layer)"),
    Kind("mask overlay", "mask overlay", "µm rms length", 1e-6, (0.1, 0.25, 0.5, 1, 2), _overlay,
         lambda b: math.sqrt(2) * budget_value(b, "overlay", "shift_sigma_um") * 1e-6, True,
         remedy="a better aligner (a stepper holds ≤ 0.2 µm; contact aligners 0.5–2 µm)"),
    Kind("mask rotation", "mask rotation", "µrad", 1e-6, (10, 30, 100, 300), _mask_rotation,
         lambda b: budget_value(b, "overlay", "rotation_sigma_urad") * 1e-6, True,
         remedy="a better aligner"),
    Kind("edge bias", "edge bias", "µm", 1e-6, (-0.5, -0.2, -0.1, 0.1, 0.2, 0.5),
         lambda v, n: replace(PartErrors(), edge_bias=v),
         lambda b: budget_value(b, "lithography", "edge_bias_sigma_um") * 1e-6,
         True,
         remedy="CD control (exposure dose and etch calibrated on the CD ladder)"),
    Kind("corner rounding", "corner rounding", "µm", 1e-6, (0.1, 0.3, 1.0),
         lambda v, n: replace(PartErrors(), corner_rounding=v),
         lambda b: budget_value(b, "lithography", "corner_rounding_um") * 1e-6, True,
         remedy="a finer mask writer"),
    Kind("surface roughness", "surface roughness", "nm rms", 1e-9, (5, 10, 20),
         lambda v, n: replace(PartErrors(), roughness=v, roughness_corr=2e-6),
         lambda b: budget_value(b, "surface", "roughness_rms_nm") * 1e-9, True,
         remedy="a smoother etch"),
    Kind("decenter across split", "decenter", "mm", 1e-3, (0.05, 0.1, 0.25),
         lambda v, n: replace(PartErrors(), mount_shift=(v, 0.0)), _decenter_sigma, False,
         remedy="a tighter die pocket in the holder (holder clearance_mm) or an alignment pin"),
    Kind("decenter along split", "decenter", "mm", 1e-3, (0.05, 0.1, 0.25),
         lambda v, n: replace(PartErrors(), mount_shift=(0.0, v)), _decenter_sigma, False,
         remedy="a tighter die pocket in the holder (clearance_mm)"),
    Kind("mount rotation", "mount rotation", "°", math.pi / 180, (0.25, 0.5, 1.0, 2.4),
         lambda v, n: replace(PartErrors(), mount_rotation=v),
         lambda b: math.radians(budget_value(b, "mounting", "rotation_sigma_deg")), True,
         remedy="index pins or a tighter pocket (holder clearance_mm), or turning the die to the split"),
    Kind("mount tilt", "mount tilt", "°", math.pi / 180, (0.5, 1, 2, 5),
         lambda v, n: replace(PartErrors(), mount_tilt=v),
         lambda b: math.radians(budget_value(b, "mounting", "tilt_sigma_deg")), False,
         remedy="a flatter die seat (the holder's pocket floor) or a shim under the die"),
    Kind("axial gap", "axial gap", "mm", 1e-3, (0.5, 1, 2, 5, 10), lambda v, n: replace(PartErrors(), axial_gap=v),
         nominal_gap, False,
         remedy="mounting the DOE at the lens's stop"),
    Kind("axial gap spread", "axial gap", "mm about the nominal gap", 1e-3, (),
         lambda v, n: replace(PartErrors(), axial_gap=v), _gap_sigma, False, _gap_part(_gap_sigma),
         _gap_part(lambda b: 0.0),
         remedy="a tighter thread stop or print tolerance of the holder (axial_gap_sigma_mm)"),
    Kind("crosstalk, uncalibrated", "sensor crosstalk", "%", 0.01, (2, 5, 10), _crosstalk(False),
         _crosstalk_value(False), False, _crosstalk_part(False),
         remedy="calibrating the dual-pixel crosstalk (white-wall captures, the paper's Eq. 30–31)"),
    Kind("crosstalk, calibrated", "sensor crosstalk", "%", 0.01, (2, 5, 10), _crosstalk(True),
         _crosstalk_value(True), False, _crosstalk_part(True),
         remedy="a per-pixel crosstalk calibration repeated before each capture session (a per-column one "
                "leaves the rows' variation, the field's along the columns and the drift)"),
)


def kind(name: str) -> Kind:
    for k in KINDS:
        if k.name == name:
            return k
    raise KeyError(name)


def budget_part(budget: dict, name: str, n_masks: int) -> PartErrors:
    """The part with one standard deviation of error ``name`` alone, for a design of ``n_masks`` masks."""
    return kind(name).budget_part(budget, n_masks)
