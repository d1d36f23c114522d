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


def _budget(**sensor):
    from doefab.tolerance.errors import load_budget

    b = load_budget()
    b["sensor"].update(sensor)
    return b


def test_a_calibration_is_judged_where_the_sensor_puts_its_smallest_ratio_and_a_tiny_ratio_in_absolute_terms():
    """The warning reads the centre row's centre and edges: with a 4.5 % slope the r→l ratio is 0.5 % at the
    right edge, where 16 rows at 5 % of full scale scatter it by ±0.078 points (√(0.005·0.995·1250 + 9·0.99) /
    (1250·4)), over the 5 % of 1 % (a ratio under 1 % is judged against 1 %) warned of, although the centre's 5 %
    ratio is scattered by 3.3 % of it; with the 2 % slope the smallest ratio, 3 %, by 4.5 %: no warning. 0.005 %
    crosstalk with 256 rows at half of full scale: none; a dim single row: ±1.2 points on the near-zero ratio of a
    sensor without r→l crosstalk, warned; no calibration, or no crosstalk: nothing."""
    from doefab.tolerance.errors import calibration_warning

    edge = calibration_warning(_budget(crosstalk_slope_percent=4.5, calibration_rows=16, calibration_level=0.05))
    assert edge and "r→l ratio at the calibrated region's right edge (0.5 %) by ±0.078 percentage points," in edge
    assert calibration_warning(_budget(calibration_rows=16, calibration_level=0.05)) is None
    # ±0.0016 points on a 0.01 % ratio (the model's least): 16 % of the ratio, nothing of the light
    assert calibration_warning(_budget(crosstalk_rl_percent=0.005, calibration_rows=256)) is None
    dim = calibration_warning(_budget(crosstalk_rl_percent=0.0, calibration_rows=1, calibration_level=0.01))
    assert dim and "r→l ratio" in dim and "±1.2 percentage points, more" in dim, dim  # no "% of it" below 1 %
    assert calibration_warning(_budget(calibrated=False, calibration_rows=1, calibration_level=0.01)) is None
    assert calibration_warning(_budget(crosstalk_lr_percent=0.0, crosstalk_rl_percent=0.0, calibration_rows=1,
                                       calibration_level=0.01)) is None


def test_a_network_level_study_warns_with_the_noise_of_the_networks_sensor():
    """``doefab tolerance --networks``: the network's captures draw the calibration with the sensor it was trained
    for; a calibration fine at the budget's noise (3 e⁻) but swamped at the network's 40 e⁻ is warned of once."""
    from doefab.cli.tolerance import _calibration_notes

    b = _budget(calibration_rows=16, calibration_level=0.05)
    assert _calibration_notes(b, None) == [] and _calibration_notes(b, {}) == []
    notes = _calibration_notes(b, {"sensor": {"read_noise_e": 40.0}})
    assert len(notes) == 1 and "40 e⁻ read noise" in notes[0]
    assert "read_noise_e" not in b["sensor"]  # the budget itself is left as it was
    dim = _budget(calibration_rows=1, calibration_level=0.01)
    assert len(_calibration_notes(dim, {})) == 1  # the same warning twice is said once
