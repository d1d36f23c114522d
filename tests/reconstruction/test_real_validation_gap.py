"""The depth gap's interval on the measured-data page (``benchmarks/real_validation.py``): a bootstrap whose
draws can be counted by hand."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rv():
    spec = importlib.util.spec_from_file_location("real_validation", ROOT / "benchmarks" / "real_validation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_constant_shift_is_its_own_interval(rv):
    assert rv.gap_interval([0.9] * 5, [0.8] * 7) == pytest.approx((0.1, 0.1), abs=1e-12)


def test_crops_of_one_scene_are_drawn_together(rv):
    """Measured crops 1, 1, 1 (one scene) and 0 (another), test scenes all 0. Drawn by scene, the mean is 1, 0.75
    or 0 (two scenes each drawn ¼ of the time both times: 0 in a quarter of the draws), so the 2.5 % point is 0;
    drawn one by one it is 0 only when all four draws take the 0 (1/256 < 2.5 %), so the 2.5 % point is 0.25."""
    real, test = [1.0, 1.0, 1.0, 0.0], [0.0] * 6
    clustered = rv.gap_interval(real, test, ["a", "a", "a", "b"], draws=4000)
    each = rv.gap_interval(real, test, draws=4000)
    assert clustered == pytest.approx((0.0, 1.0))
    assert each == pytest.approx((0.25, 1.0))
