"""Tolerance budgets (TOML, units in the key names) and the errors of one sampled part.

Each Monte Carlo sample draws its errors from its own ``numpy.random.SeedSequence(seed).spawn`` child, so the
same seed gives the same parts, bit for bit, whatever the number of workers or the backend.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.io import read_toml

__all__ = ["PartErrors", "load_budget", "sample_errors", "budget_value", "DEFAULT_BUDGET", "BUDGET_KEYS"]

DEFAULT_BUDGET = Path(__file__).with_name("budget.toml")

# section -> key -> (min, max) plausible range in the key's unit
BUDGET_KEYS = {
    "etch": {"systematic_sigma_percent": (0, 50), "random_sigma_percent": (0, 50)},
    "overlay": {"shift_sigma_um": (0, 20), "rotation_sigma_urad": (0, 5000)},
    "lithography": {"edge_bias_sigma_um": (0, 5), "corner_rounding_um": (0, 5)},
    "surface": {"roughness_rms_nm": (0, 200), "correlation_length_um": (0.1, 1000)},
    "mounting": {"decenter_max_mm": (0, 5), "rotation_sigma_deg": (0, 30)},
    "sensor": {"crosstalk_lr_percent": (0, 45), "crosstalk_rl_percent": (0, 45), "calibrated": None},
    "spec": {"metric_min": (0, 1)},
}


@dataclass
class PartErrors:
    """The errors of one fabricated and mounted part (SI units)."""

    depth_scale: tuple = (1.0, 1.0, 1.0, 1.0)
    overlay: tuple = ((0.0, 0.0),) * 4
    rotation: tuple = (0.0,) * 4
    edge_bias: float = 0.0
    corner_rounding: float = 0.0
    roughness: float = 0.0
    roughness_corr: float = 2e-6
    mount_shift: tuple = (0.0, 0.0)  # metres: across (x) and along (y) the split line
    mount_rotation: float = 0.0
    crosstalk: tuple = (0.0, 0.0)  # (α_l→r, α_r→l)
    calibrated: bool = True
    seed: int = 0
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return asdict(self)


def load_budget(path: str | Path | None = None) -> dict:
    """Read and validate a budget file (every problem listed with its key)."""
    p = Path(path) if path is not None else DEFAULT_BUDGET
    data = read_toml(p, "budget file")
    problems = []
    for sec, val in data.items():
        if sec not in BUDGET_KEYS:
            problems.append(f"unknown section [{sec}]")
            continue
        for key, v in val.items():
            if key not in BUDGET_KEYS[sec]:
                problems.append(f"unknown key {sec}.{key}")
            elif BUDGET_KEYS[sec][key] is None:
                if not isinstance(v, bool):
                    problems.append(f"{sec}.{key} must be true or false")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                problems.append(f"{sec}.{key} must be a number")
            elif not BUDGET_KEYS[sec][key][0] <= v <= BUDGET_KEYS[sec][key][1]:
                lo, hi = BUDGET_KEYS[sec][key]
                problems.append(f"{sec}.{key} = {v} is outside {lo}–{hi} (check the unit in the key's name)")
    if problems:
        raise DoefabError(f"{p}: " + "; ".join(problems))
    return data


def budget_value(budget: dict, sec: str, key: str, default: float = 0.0) -> float:
    """``budget[sec][key]`` as a float (``default`` when absent)."""
    return float(budget.get(sec, {}).get(key, default))


def sample_errors(budget: dict, rng: np.random.Generator, seed: int = 0) -> PartErrors:
    """One part's errors drawn from ``budget`` with ``rng``."""
    sys_ = rng.normal(0, budget_value(budget, "etch", "systematic_sigma_percent") / 100)
    rnd = rng.normal(0, budget_value(budget, "etch", "random_sigma_percent") / 100, 4)
    depth = tuple(float(np.clip(1 + sys_ + r, 0.5, 1.5)) for r in rnd)
    sig = budget_value(budget, "overlay", "shift_sigma_um") * 1e-6
    overlay = tuple((float(a), float(b)) for a, b in rng.normal(0, sig, (4, 2))) if sig > 0 else ((0.0, 0.0),) * 4
    rot = tuple(float(v) for v in rng.normal(0, budget_value(budget, "overlay", "rotation_sigma_urad") * 1e-6, 4))
    bias = float(rng.normal(0, budget_value(budget, "lithography", "edge_bias_sigma_um") * 1e-6))
    dmax = budget_value(budget, "mounting", "decenter_max_mm") * 1e-3
    shift = tuple(float(v) for v in rng.uniform(-dmax, dmax, 2))
    mrot = float(rng.normal(0, math.radians(budget_value(budget, "mounting", "rotation_sigma_deg"))))
    return PartErrors(depth_scale=depth, overlay=overlay, rotation=rot, edge_bias=bias,
                      corner_rounding=budget_value(budget, "lithography", "corner_rounding_um") * 1e-6,
                      roughness=budget_value(budget, "surface", "roughness_rms_nm") * 1e-9,
                      roughness_corr=budget_value(budget, "surface", "correlation_length_um", 2.0) * 1e-6,
                      mount_shift=shift, mount_rotation=mrot,
                      crosstalk=(budget_value(budget, "sensor", "crosstalk_lr_percent") / 100,
                                 budget_value(budget, "sensor", "crosstalk_rl_percent") / 100),
                      calibrated=bool(budget.get("sensor", {}).get("calibrated", True)),
                      seed=int(seed))
