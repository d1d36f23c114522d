"""Network-level judge: a perfect part scores as the nominal design, and the depth network reads the measured
PSF pair it is given (its cross-blur cost volume) — a mounting error then changes what the judge reports."""

from pathlib import Path

import numpy as np

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


def test_the_judge_records_captures_with_the_sensor_its_network_was_trained_for():
    """The network's weights record names its sensor: the judge's captures use that noise and (hyperspectral) the
    response its architecture record holds; records without one are the default camera's."""
    from types import SimpleNamespace

    from doefab.imaging.sensor import Sensor
    from doefab.tolerance.netjudge import NetworkJudge

    bands = np.arange(400, 701, 10) * 1e-9
    nikon = Sensor("Nikon D5100", full_well_e=5000.0, read_noise_e=4.0)
    judge = NetworkJudge.__new__(NetworkJudge)
    judge.task = "hyperspectral"
    judge.rec = SimpleNamespace(meta={"arch": {"response": nikon.rgb(bands).tolist()}, "sensor": nikon.record()},
                                pair=SimpleNamespace(wavelengths=bands))
    t, noise = judge.sensor()
    assert np.allclose(t, nikon.rgb(bands)) and (noise.full_well_e, noise.read_noise_e) == (5000.0, 4.0)
    judge.rec.meta = {"arch": {}}  # shipped weights recorded before sensors were
    t, noise = judge.sensor()
    assert np.allclose(t, Sensor().rgb(bands)) and (noise.full_well_e, noise.read_noise_e) == (25000.0, 3.0)
