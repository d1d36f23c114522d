"""Every key of a tolerance budget and every limit of its spec has a range, and whole-number keys take whole
numbers: a budget outside them is refused by ``load_budget`` with the key, the value and the range named."""

import pytest

from doefab.errors import DoefabError
from doefab.tolerance.errors import BUDGET_KEYS, DEFAULT_BUDGET, WHOLE_KEYS, budget_problems, load_budget
from doefab.tolerance.spec import DELIVERED, limit_range, spec_keys


def _numeric_keys():
    return [(sec, key, rng) for sec, keys in BUDGET_KEYS.items() for key, rng in (keys or {}).items() if rng]


def _cases():
    """(table, key, a TOML value outside what the key takes) for every budget key and every spec limit."""
    out = []
    for sec, key, (lo, hi) in _numeric_keys():
        out += [(sec, key, f"{lo - 1:g}"), (sec, key, f"{hi * 10 + 1:g}"), (sec, key, "nan")]
    for task in DELIVERED:
        for key in spec_keys(task):
            lo, hi, _ = limit_range(task, key)
            out += [(f"spec.{task}", key, f"{lo - 1:g}"), (f"spec.{task}", key, f"{hi + 1:g}"),
                    (f"spec.{task}", key, "inf")]
    out += [(sec, key, v) for sec, key in sorted(WHOLE_KEYS) for v in ("1536.5", "16.7")]
    return out


@pytest.mark.parametrize("table, key, value", _cases())
def test_a_value_outside_a_keys_range_is_refused_naming_it(tmp_path, table, key, value):
    p = tmp_path / "budget.toml"
    p.write_text(f"[{table}]\n{key} = {value}\n")
    with pytest.raises(DoefabError) as exc:
        load_budget(p)
    msg = str(exc.value)
    assert f"{table}.{key}" in msg, msg
    assert "–" in msg or "whole number" in msg, msg  # the range, or the whole number to give


def test_the_limits_spans_match_their_metrics():
    """A fraction (PSF metric, δ<1.25) lies in 0–1 and a margin below the nominal part is ≥ 0; SSIM in −1–1; SAM an
    angle in 0–π; and every limit the shipped budget sets lies within its range."""
    import math

    assert limit_range("hdr", "psf_metric_min")[:2] == (0.0, 1.0)
    assert limit_range("depth", "delta125_min")[:2] == (0.0, 1.0)
    assert limit_range("hyperspectral", "ssim_min")[:2] == (-1.0, 1.0)
    assert limit_range("hyperspectral", "ssim_loss_max")[:2] == (0.0, 2.0)
    assert limit_range("hyperspectral", "sam_rad_max") == (0.0, math.pi, "rad")
    assert limit_range("hdr", "psnr_highlight_db_loss_max")[2] == "dB"
    assert budget_problems(DEFAULT_BUDGET) == []


def test_every_problem_of_a_budget_is_listed_together(tmp_path):
    """The user trial's budget (issue 37, row 4): each of its five problems named at once."""
    p = tmp_path / "budget.toml"
    p.write_text("[etch]\nsystematic_sigma_percent = -3\n[sensor]\ncalibration_rows = 1.5\ncalibrated_width_px = 16.7\n"
                 "[spec.hyperspectral]\npsf_metric_min = 5.0\nsam_rad_max = -0.5\n")
    problems = budget_problems(p)
    assert len(problems) == 5, problems
    for needle in ("systematic_sigma_percent = -3", "calibration_rows = 1.5", "e.g. 2", "calibrated_width_px = 16.7",
                   "e.g. 17", "psf_metric_min = 5.0 is outside 0–1", "sam_rad_max = -0.5 is outside 0–3.142 rad"):
        assert any(needle in q for q in problems), needle
    p.write_text("[sensor]\ncalibration_rows = 1536.0\ncalibrated_width_px = 2048\n")  # whole, written as a float
    assert budget_problems(p) == []
