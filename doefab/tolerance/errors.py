"""Tolerance budgets (TOML, units in the key names) and the errors of one sampled part.

Each Monte Carlo sample draws its errors from its own ``numpy.random.SeedSequence(seed).spawn`` child, so the
same seed gives the same parts, bit for bit, whatever the number of workers or the backend.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError, problems_error
from doefab.imaging.sensor import DEFAULT_FULL_WELL_E, DEFAULT_READ_NOISE_E, PoissonGaussian
from doefab.io import read_toml
from doefab.tolerance.sources import (budget_keys, budget_value, drawn_fields, nominal_gap, sensor_errors,
                                      whole_keys)

__all__ = ["PartErrors", "load_budget", "budget_problems", "sample_errors", "budget_value", "DEFAULT_BUDGET",
           "is_shipped_budget", "names_default_budget", "BUDGET_KEYS", "WHOLE_KEYS", "holder_mounting", "nominal_gap",
           "sensor_errors", "crosstalk_ratios", "sensor_crosstalk", "budget_values", "calibration_warning",
           "CALIBRATION_SCATTER_MAX", "CALIBRATION_RATIO_FLOOR", "with_sensor_noise"]

DEFAULT_BUDGET = Path(__file__).with_name("budget.toml")

# section -> key -> (min, max) plausible range in the key's unit, from the sources of error (``sources.SOURCES``)
BUDGET_KEYS = budget_keys()
# keys that count something: whole numbers only (3072 or 3072.0, not 1.5)
WHOLE_KEYS = whole_keys()
# a crosstalk calibration whose per-column ratios scatter by more than this fraction of the ratio is warned of: above
# the sensor model's own row-to-row (2 %) and session-to-session (3 %) changes (``sensorcrosstalk``)
CALIBRATION_SCATTER_MAX = 0.05
# below this a ratio's calibration error is judged against this ratio: a small share of the light however relative
CALIBRATION_RATIO_FLOOR = 0.01


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
    mount_tilt: float = 0.0  # radians: the die's normal off the optical axis (the light meets it at this angle)
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


def names_default_budget(name, base: str | Path | None = None) -> bool:
    """Whether ``name`` is the shipped budget's name: None, or the text ``default`` in any case and spacing where no
    file of that name exists (relative to ``base``, else the working directory): one rule for a scene's
    ``tolerance.budget``, ``--budget`` and ``load_budget``.

    >>> names_default_budget("Default"), names_default_budget("my_budget.toml")
    (True, False)
    """
    if name is None:
        return True
    if not isinstance(name, str) or name.strip().lower() != "default":
        return False
    return not (Path(base) / name if base is not None else Path(name)).exists()


def is_shipped_budget(path: str | Path | None) -> bool:
    """Whether a budget path names the shipped default budget (None or ``default``, or ``DEFAULT_BUDGET`` by any
    path)."""
    return names_default_budget(path) or Path(path).resolve() == DEFAULT_BUDGET.resolve()


def load_budget(path: str | Path | None = None) -> dict:
    """Read and validate a budget file (every problem listed with its key). A key the file leaves out takes the
    shipped default budget's value; ``budget["defaults_used"]`` lists those keys (a ``[spec.<task>]`` table the
    file gives replaces the default's table of that task as a whole)."""
    p = DEFAULT_BUDGET if names_default_budget(path) else Path(path)
    data = read_toml(p, "budget file")
    problems = _problems(data)
    if problems:
        raise problems_error(p, problems)
    if is_shipped_budget(path):
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


def budget_values(budget: dict) -> dict:
    """A loaded budget's values without its ``defaults_used`` record (what its digests are taken of: the same
    values give the same budget, whichever file spelt them out).

    Example: ``budget_values(load_budget())["mounting"]``."""
    return {k: v for k, v in budget.items() if k != "defaults_used"}


def budget_problems(path: str | Path) -> list[str]:
    """Every problem of a budget file, each naming its key, the value and the range (a DoefabError when the file
    is missing or not TOML): what ``load_budget`` refuses, for a scene check to list with its own."""
    return _problems(read_toml(path, "budget file"))


def _problems(data: dict) -> list[str]:
    from doefab.tolerance.spec import check_spec

    problems, keys, whole = [], budget_keys(), whole_keys()  # the table as it is now
    for sec, val in data.items():
        if sec not in keys:
            problems.append(f"unknown section [{sec}]")
            continue
        if not isinstance(val, dict):
            problems.append(f"{sec} must be a table [{sec}]")
            continue
        if keys[sec] is None:
            problems += check_spec(val)
            continue
        for key, v in val.items():
            if key not in keys[sec]:
                problems.append(f"unknown key {sec}.{key}")
            elif keys[sec][key] is None:
                if not isinstance(v, bool):
                    problems.append(f"{sec}.{key} must be true or false")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                lo, hi = keys[sec][key]
                problems.append(f"{sec}.{key} must be a number within {lo}–{hi}, got {v!r}")
            elif not keys[sec][key][0] <= v <= keys[sec][key][1]:
                lo, hi = keys[sec][key]
                problems.append(f"{sec}.{key} = {v} is outside {lo}–{hi} (check the unit in the key's name)")
            elif (sec, key) in whole and v != int(v):
                lo, hi = keys[sec][key]
                problems.append(f"{sec}.{key} = {v} counts something: give a whole number, e.g. "
                                f"{min(max(round(v), lo), hi)}")
    return problems


def sample_errors(budget: dict, rng: np.random.Generator, seed: int = 0, *, n_masks: int) -> PartErrors:
    """One part's errors drawn from ``budget`` with ``rng``, for a design of ``n_masks`` masks (log2 of its levels;
    with 4 masks the draws are those of every 16-level study): each source of error's draw, in the order of
    ``sources.SOURCES``.

    Example: ``sample_errors(load_budget(), np.random.default_rng(0), n_masks=4).depth_scale`` → four etch-depth
    scale factors near 1."""
    return PartErrors(**drawn_fields(budget, rng, n_masks), seed=int(seed))


def sensor_crosstalk(err: PartErrors):
    """The true crosstalk (``imaging.sensorcrosstalk.SensorCrosstalk``) of the part's camera's sensor, seeded by
    the part."""
    from doefab.imaging.sensorcrosstalk import SensorCrosstalk

    return SensorCrosstalk(err.crosstalk, err.crosstalk_slope, width_px=err.calibrated_width_px, seed=err.seed)


def crosstalk_ratios(err: PartErrors, columns, noise=None, rows=None) -> tuple:
    """(α_l→r, α_r→l, α̂_l→r, α̂_r→l) at sensor ``columns`` (pixels from the centre column): the part's camera's
    true crosstalk (``imaging.sensorcrosstalk.SensorCrosstalk`` of its sensor, seeded by the part, in its capture
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


def with_sensor_noise(budget: dict, sensor) -> dict:
    """``budget`` (changed in place, and returned) with the noise of ``sensor`` (an ``imaging.sensor.Sensor``: a
    scene's) in its ``[sensor]`` section where that differs from the default sensor's: the noise the PSF-level
    judge's crosstalk calibration draws.

    Example: ``with_sensor_noise(load_budget(), Sensor(read_noise_e=8.0))["sensor"]["read_noise_e"]`` → 8.0."""
    from doefab.imaging.sensor import Sensor

    noise, default = sensor.record(with_response=False), Sensor().record(with_response=False)
    budget.setdefault("sensor", {}).update({k: v for k, v in noise.items() if v != default[k]})
    return budget


def calibration_warning(budget: dict) -> str | None:
    """A warning where the budget's crosstalk calibration (``[sensor]``: rows, exposure and the sensor's noise) leaves
    a column's ratio scattered by more than ``CALIBRATION_SCATTER_MAX`` of it (``imaging.crosstalk
    .calibration_scatter``; a ratio under ``CALIBRATION_RATIO_FLOOR`` counted as that much, its error a small share
    of the light however relative), at the centre row's centre and edges, where the sensor model
    (``sensor_crosstalk``) puts the smallest ratios: its noise, not the sensor, then sets what the calibration leaves
    in every part's captures. None for a calibration within it, an uncalibrated camera or none of either crosstalk.

    Example: ``calibration_warning(load_budget())`` is None (3072 rows at half of full scale: 0.09 % of the smallest
    ratio, 3 %)."""
    from doefab.imaging.crosstalk import calibration_scatter
    from doefab.imaging.sensorcrosstalk import DRIFT_SIGMA, ROW_SIGMA, SensorCrosstalk

    s = sensor_errors(budget)
    if not s["calibrated"] or not any(s["crosstalk"]):
        return None  # the stage calibrates only a sensor with crosstalk (``crosstalk_ratios``)
    rows, level, fw, rn, w = (s[k] for k in ("calibration_rows", "calibration_level", "full_well_e",
                                             "read_noise_e", "calibrated_width_px"))
    where = ("left edge", "centre", "right edge")
    sensor = SensorCrosstalk(s["crosstalk"], s["crosstalk_slope"], row_sigma=0.0, width_px=w)
    ratios = sensor.ratios([0.0], [-w / 2, 0.0, w / 2], session=None)

    def excess(a: float) -> float:  # the scatter against what is warned of, in its units
        warned = CALIBRATION_SCATTER_MAX * max(a, CALIBRATION_RATIO_FLOOR)
        return calibration_scatter(a, rows, level, fw, rn) * a / warned

    alpha, name, at = max(((float(a), name, at) for name, r in zip(("l→r", "r→l"), ratios)
                           for a, at in zip(r[0], where) if a > 0), key=lambda t: excess(t[0]), default=(0, "", ""))
    if alpha <= 0 or excess(alpha) <= 1:
        return None
    rel = calibration_scatter(alpha, rows, level, fw, rn)
    return (f"tolerance budget [sensor]: a crosstalk calibration of {rows} row{'s' * (rows != 1)} at "
            f"calibration_level = {level:g} on a sensor of {fw:g} e⁻ full well and {rn:g} e⁻ read noise scatters "
            f"the {name} ratio at the calibrated region's {at} ({100 * alpha:.2g} %) by ±{100 * rel * alpha:.2g} "
            f"percentage points{f' ({100 * rel:.0f} % of it)' if alpha >= CALIBRATION_RATIO_FLOOR else ''}, more "
            f"than the sensor's own changes from row to row "
            f"({100 * ROW_SIGMA:g} %) and between sessions ({100 * DRIFT_SIGMA:g} %): the calibration's noise sets "
            f"the crosstalk residual of every part; average more rows or expose the white wall brighter (the "
            f"shipped budget: calibration_rows = 3072, calibration_level = 0.5) unless this is your lab's "
            f"calibration")


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
