"""Network-level judge: a perfect part scores as the nominal design, and the depth network reads the measured
PSF pair it is given (its cross-blur cost volume) — a mounting error then changes what the judge reports."""

from pathlib import Path

import pytest

from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge
from doefab.tolerance.netjudge import NetworkJudge

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def judge():
    return NetworkJudge(PSFJudge(REPO / "masks" / "half-ring" / "design", supersample=1), images=1, size=64)


def test_perfect_part_reads_the_same_with_either_psf(judge):
    r = judge.evaluate(PartErrors())
    assert r["nominal_psf"].keys() == {"mae", "rmse", "log10", "delta125"}
    for k, v in r["nominal_psf"].items():
        assert r["measured_psf"][k] == pytest.approx(v, rel=1e-3, abs=1e-4)


def test_depth_network_uses_the_measured_pair(judge):
    r = judge.evaluate(PartErrors(mount_shift=(400e-6, 0.0)))  # 0.4 mm across the split line
    assert r["nominal_psf"]["mae"] != pytest.approx(r["measured_psf"]["mae"], rel=1e-4)


def test_the_error_free_part_is_judged_once_and_handed_out_by_copy(judge):
    first = judge.evaluate(PartErrors())
    first["nominal_psf"]["mae"] = -1.0  # a caller's edit must not reach the next call
    again = judge.evaluate(PartErrors())
    cold = NetworkJudge(judge.base, images=1, size=64).evaluate(PartErrors())
    assert again["nominal_psf"]["mae"] > 0
    for label in ("nominal_psf", "measured_psf"):
        for k, v in cold[label].items():
            assert again[label][k] == pytest.approx(v, rel=1e-6, abs=1e-9)
