"""Tolerance budgets (TOML, units in the key names) and the errors of one sampled part.

Each Monte Carlo sample draws its errors from its own ``numpy.random.SeedSequence(seed).spawn`` child, so the
same seed gives the same parts, bit for bit, whatever the number of workers or the backend.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E, PoissonGaussian
from doefab.io import read_toml

__all__ = ["PartErrors", "load_budget", "budget_problems", "sample_errors", "budget_value", "DEFAULT_BUDGET",
           "BUDGET_KEYS", "WHOLE_KEYS", "holder_mounting", "nominal_gap", "sensor_errors", "crosstalk_ratios",
           "sensor_crosstalk"]

DEFAULT_BUDGET = Path(__file__).with_name("budget.toml")

# section -> key -> (min, max) plausible range in the key's unit
BUDGET_KEYS = {
    "etch": {"systematic_sigma_percent": (0, 50), "random_sigma_percent": (0, 50)},
    "overlay": {"shift_sigma_um": (0, 20), "rotation_sigma_urad": (0, 5000)},
    "lithography": {"edge_bias_sigma_um": (0, 5), "corner_rounding_um": (0, 5)},
    "surface": {"roughness_rms_nm": (0, 200), "correlation_length_um": (0.1, 1000)},
    "mounting": {"decenter_max_mm": (0, 5), "rotation_sigma_deg": (0, 30), "axial_gap_mm": (0, 50),
                 "axial_gap_sigma_mm": (0, 10), "pupil_behind_glass_mm": (0, 45)},
    "sensor": {"crosstalk_lr_percent": (0, 49.9), "crosstalk_rl_percent": (0, 49.9), "crosstalk_slope_percent": (0, 20),
               "calibrated": None, "calibration_rows": (1, 100000), "calibration_level": (0.01, 1),
               "calibrated_width_px": (16, 100000)},
    "spec": None,  # per-task tables, checked by doefab.tolerance.spec
}
# keys that count something: whole numbers only (3072 or 3072.0, not 1.5)
WHOLE_KEYS = {("sensor", "calibration_rows"), ("sensor", "calibrated_width_px")}


@dataclass
class PartErrors:
    """The errors of one fabricated and mounted part (SI units).

    ``depth_scale``, ``overlay`` and ``rotation`` hold one entry per mask of the design (M = log2 L), or nothing
    for a part whose masks are all nominal (:meth:`for_masks` fills them in for a design's M)."""

    depth_scale: tuple = ()
    overlay: tuple = ()
    rotation: tuple = ()
    edge_bias: float = 0.0
    corner_rounding: float = 0.0
    roughness: float = 0.0
    roughness_corr: float = 2e-6
    mount_shift: tuple = (0.0, 0.0)  # metres: across (x) and along (y) the split line
    mount_rotation: float = 0.0
    axial_gap: float = 0.0  # metres: DOE in front of the aperture plane (doefab.optics.gap)
    crosstalk: tuple = (0.0, 0.0)  # (α_l→r, α_r→l) at the sensor's centre column
    crosstalk_slope: float = 0.0  # change of α_l→r (up) and α_r→l (down) from the centre to the calibrated edge
    calibrated: bool = True  # unmixed with ratios estimated from simulated noisy white-wall captures
    calibration_rows: int = 3072  # rows averaged per column by that calibration (the paper's § 5.1: 3072 × 3072)
    calibration_level: float = 0.5  # the white wall's exposure, fraction of full scale
    calibrated_width_px: int = 3072
    full_well_e: float = DEFAULT_FULL_WELL_E  # the sensor's noise, which its crosstalk calibration draws
    read_noise_e: float = DEFAULT_READ_NOISE_E
    seed: int = 0
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return asdict(self)

    def for_masks(self, n_masks: int) -> "PartErrors":
        """This part with one per-mask entry for each of ``n_masks`` masks (a DoefabError naming the mask count when
        an entry list has another length)."""
        from doefab.tolerance.fabricate import per_mask

        return replace(self, **{k: per_mask(k, getattr(self, k), n_masks) for k in ("depth_scale", "overlay",
                                                                                     "rotation")})


def load_budget(path: str | Path | None = None) -> dict:
    """Read and validate a budget file (every problem listed with its key). A key the file leaves out takes the
    shipped default budget's value; ``budget["defaults_used"]`` lists those keys (a ``[spec.<task>]`` table the
    file gives replaces the default's table of that task as a whole)."""
    p = Path(path) if path is not None else DEFAULT_BUDGET
    data = read_toml(p, "budget file")
    problems = _problems(data)
    if problems:
        raise DoefabError(f"{p}: " + "; ".join(problems))
    if path is None or p.resolve() == DEFAULT_BUDGET.resolve():
        return {**data, "defaults_used": []}
    base = read_toml(DEFAULT_BUDGET, "default budget")
    used = []
    merged = {sec: dict(val) for sec, val in data.items()}
    for sec, val in base.items():
        have = merged.setdefault(sec, {})
        for key, v in val.items():
            if key not in have:
                have[key] = v
                used.append(f"{sec}.{key}")
    return {**merged, "defaults_used": used}


def budget_problems(path: str | Path) -> list[str]:
    """Every problem of a budget file, each naming its key, the value and the range (a DoefabError when the file
    is missing or not TOML): what ``load_budget`` refuses, for a scene check to list with its own."""
    return _problems(read_toml(path, "budget file"))


def _problems(data: dict) -> list[str]:
    from doefab.tolerance.spec import check_spec

    problems = []
    for sec, val in data.items():
        if sec not in BUDGET_KEYS:
            problems.append(f"unknown section [{sec}]")
            continue
        if not isinstance(val, dict):
            problems.append(f"{sec} must be a table [{sec}]")
            continue
        if BUDGET_KEYS[sec] is None:
            problems += check_spec(val)
            continue
        for key, v in val.items():
            if key not in BUDGET_KEYS[sec]:
                problems.append(f"unknown key {sec}.{key}")
            elif BUDGET_KEYS[sec][key] is None:
                if not isinstance(v, bool):
                    problems.append(f"{sec}.{key} must be true or false")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                lo, hi = BUDGET_KEYS[sec][key]
                problems.append(f"{sec}.{key} must be a number within {lo}–{hi}, got {v!r}")
            elif not BUDGET_KEYS[sec][key][0] <= v <= BUDGET_KEYS[sec][key][1]:
                lo, hi = BUDGET_KEYS[sec][key]
                problems.append(f"{sec}.{key} = {v} is outside {lo}–{hi} (check the unit in the key's name)")
            elif (sec, key) in WHOLE_KEYS and v != int(v):
                lo, hi = BUDGET_KEYS[sec][key]
                problems.append(f"{sec}.{key} = {v} counts something: give a whole number, e.g. "
                                f"{min(max(round(v), lo), hi)}")
    return problems


def budget_value(budget: dict, sec: str, key: str, default: float = 0.0) -> float:
    """``budget[sec][key]`` as a float (``default`` when absent)."""
    return float(budget.get(sec, {}).get(key, default))


def sample_errors(budget: dict, rng: np.random.Generator, seed: int = 0, *, n_masks: int) -> PartErrors:
    """One part's errors drawn from ``budget`` with ``rng``, for a design of ``n_masks`` masks (log2 of its levels;
    with 4 masks the draws are those of every 16-level study)."""
    m = n_masks
    sys_ = rng.normal(0, budget_value(budget, "etch", "systematic_sigma_percent") / 100)
    rnd = rng.normal(0, budget_value(budget, "etch", "random_sigma_percent") / 100, m)
    depth = tuple(float(np.clip(1 + sys_ + r, 0.5, 1.5)) for r in rnd)
    sig = budget_value(budget, "overlay", "shift_sigma_um") * 1e-6
    overlay = tuple((float(a), float(b)) for a, b in rng.normal(0, sig, (m, 2))) if sig > 0 else ((0.0, 0.0),) * m
    rot = tuple(float(v) for v in rng.normal(0, budget_value(budget, "overlay", "rotation_sigma_urad") * 1e-6, m))
    bias = float(rng.normal(0, budget_value(budget, "lithography", "edge_bias_sigma_um") * 1e-6))
    dmax = budget_value(budget, "mounting", "decenter_max_mm") * 1e-3
    shift = tuple(float(v) for v in rng.uniform(-dmax, dmax, 2))
    mrot = float(rng.normal(0, math.radians(budget_value(budget, "mounting", "rotation_sigma_deg"))))
    gap = max(0.0, nominal_gap(budget) + float(rng.normal(0, budget_value(budget, "mounting", "axial_gap_sigma_mm")
                                                            * 1e-3)))
    return PartErrors(depth_scale=depth, overlay=overlay, rotation=rot, edge_bias=bias,
                      corner_rounding=budget_value(budget, "lithography", "corner_rounding_um") * 1e-6,
                      roughness=budget_value(budget, "surface", "roughness_rms_nm") * 1e-9,
                      roughness_corr=budget_value(budget, "surface", "correlation_length_um", 2.0) * 1e-6,
                      mount_shift=shift, mount_rotation=mrot, axial_gap=gap,
                      **sensor_errors(budget), seed=int(seed))


def sensor_errors(budget: dict) -> dict:
    """The ``PartErrors`` fields of the budget's ``[sensor]`` section (dual-pixel crosstalk and its calibration; the
    sensor's noise where a scene's ``[sensor]`` put it there, the default sensor's otherwise)."""
    g = partial(budget_value, budget, "sensor")
    return {"crosstalk": (g("crosstalk_lr_percent") / 100, g("crosstalk_rl_percent") / 100),
            "crosstalk_slope": g("crosstalk_slope_percent") / 100,
            "calibrated": bool(budget.get("sensor", {}).get("calibrated", True)),
            "calibration_rows": int(g("calibration_rows", 3072)), "calibration_level": g("calibration_level", 0.5),
            "calibrated_width_px": int(g("calibrated_width_px", 3072)),
            "full_well_e": g("full_well_e", DEFAULT_FULL_WELL_E),
            "read_noise_e": g("read_noise_e", DEFAULT_READ_NOISE_E)}


def sensor_crosstalk(err: PartErrors):
    """The true crosstalk (``imaging.crosstalk.SensorCrosstalk``) of the part's camera's sensor, seeded by the part."""
    from doefab.imaging.crosstalk import SensorCrosstalk

    return SensorCrosstalk(err.crosstalk, err.crosstalk_slope, width_px=err.calibrated_width_px, seed=err.seed)


def crosstalk_ratios(err: PartErrors, columns, noise=None, rows=None) -> tuple:
    """(α_l→r, α_r→l, α̂_l→r, α̂_r→l) at sensor ``columns`` (pixels from the centre column): the part's camera's
    true crosstalk (``imaging.crosstalk.SensorCrosstalk`` of its sensor, seeded by the part, in its capture
    session) as [len(rows), len(columns)] maps at sensor ``rows`` (None: per column on the centre row), and the
    per-column estimate its calibration gives (simulated white-wall captures with ``noise``, None: the part's
    sensor's; the estimate is the true ratios when the camera is not calibrated — it is then not used)."""
    sensor = sensor_crosstalk(err)
    a, b = sensor.ratios([0.0] if rows is None else rows, columns)
    a, b = (a[0], b[0]) if rows is None else (a, b)
    if not err.calibrated:
        return a, b, a, b
    noise = PoissonGaussian(err.full_well_e, err.read_noise_e) if noise is None else noise
    rng = np.random.default_rng(np.random.SeedSequence([int(err.seed), 29]))
    a_hat, b_hat = sensor.calibrate(columns, err.calibration_rows, noise, rng, err.calibration_level)
    return a, b, a_hat, b_hat


def nominal_gap(budget: dict) -> float:
    """Nominal DOE-to-aperture-plane distance (metres): the holder's DOE-to-glass distance plus the depth of the
    lens's entrance pupil behind its front glass."""
    return (budget_value(budget, "mounting", "axial_gap_mm")
            + budget_value(budget, "mounting", "pupil_behind_glass_mm")) * 1e-3


def holder_mounting(holder_json: str | Path) -> dict:
    """The ``[mounting]`` entries a built holder implies (read from its ``holder.json``).

    - decenter bound = the die-to-pocket clearance per side (the die can slide that far in its pocket);
    - rotation: a square die of half-width a in a pocket with clearance c turns at most θ ≈ c / a before a corner
      touches (a·(cos θ + sin θ) = a + c); the screws and index notches keep it well inside that, so θ/4 is 1 σ
      (the same rule as the shipped budget);
    - axial gap = the DOE-to-front-glass distance the holder's checks measured on its mesh.
    """
    p = Path(holder_json)
    if p.is_dir():
        p = p / "holder.json"
    if not p.is_file():
        raise DoefabError(f"{p}: no holder.json here (build one with doefab holder --out DIR)")
    import json

    try:
        data = json.loads(p.read_text())
        params, checks = data["parameters"], data["checks"]
        clearance = float(checks.get("die_to_pocket_gap_mm", params["clearance_mm"]))
        half_width = min(float(params["die_width_mm"]), float(params["die_height_mm"])) / 2
        doe_to_glass = float(checks["doe_to_lens_mm"])
    except (ValueError, KeyError, TypeError) as e:
        raise DoefabError(f"{p} is not a doefab holder.json (missing or bad {e}): rebuild it with doefab holder") from None
    if not checks.get("passed", False):
        raise DoefabError(f"{p}: this holder failed its checks; fix and rebuild it before judging its tolerances")
    theta = math.atan2(clearance, half_width)
    return {"decenter_max_mm": clearance, "rotation_sigma_deg": math.degrees(theta) / 4, "axial_gap_mm": doe_to_glass}
