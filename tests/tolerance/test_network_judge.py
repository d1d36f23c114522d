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


def test_a_decentred_part_costs_the_nominal_reading_and_its_measured_pair_wins_it_back(judge, monkeypatch):
    """The DOE off centre across the split line: told the nominal PSF, the depth network reads the part's
    captures worse the larger the decenter (MAE 0.41 m perfect, 0.56 m at 0.2 mm, 0.93 m at 0.4 mm), at 0.4 mm
    worse than a depth-blind guess (the scene's median depth everywhere, 0.84 m) that the perfect part's reading
    halves; told the part's own PSF pair, it reads them about as well as the perfect part's (within 15 %). The
    judge's 0.4 mm numbers are those of the captures it rendered, each reconstruction repeated here and its MAE
    computed with numpy."""
    import doefab.reconstruction.specs as specs

    perfect = judge.evaluate(PartErrors())["nominal_psf"]["mae"]
    small = judge.evaluate(PartErrors(mount_shift=(200e-6, 0.0)))
    seen = {}
    real_batch, real_pair = specs.make_batch, judge.pair
    monkeypatch.setattr(specs, "make_batch", lambda *a, **k: seen.setdefault("batch", real_batch(*a, **k)))
    monkeypatch.setattr(judge, "pair", lambda *a, **k: seen.setdefault("pair", real_pair(*a, **k)))
    r = judge.evaluate(PartErrors(mount_shift=(400e-6, 0.0)))
    coded, uncoded, target = seen["batch"]
    t = target[0].numpy()
    mae = {label: float(np.abs(np.asarray(judge.rec(coded[0], uncoded[0], psf=psf)) - t).mean())
           for label, psf in (("nominal_psf", None), ("measured_psf", seen["pair"]))}
    for label, value in mae.items():
        assert r[label]["mae"] == pytest.approx(value, rel=1e-5), label
    blind = float(np.abs(t - np.median(t)).mean())
    assert perfect < 0.75 * blind and perfect < small["nominal_psf"]["mae"] < mae["nominal_psf"]
    assert blind < mae["nominal_psf"]
    for measured in (small["measured_psf"]["mae"], mae["measured_psf"]):
        assert measured == pytest.approx(perfect, rel=0.15)


def test_the_error_free_part_is_judged_once_and_handed_out_by_copy(judge):
    first = judge.evaluate(PartErrors())
    first["nominal_psf"]["mae"] = -1.0  # a caller's edit must not reach the next call
    again = judge.evaluate(PartErrors())
    cold = NetworkJudge(judge.base, images=1, size=64).evaluate(PartErrors())
    assert again["nominal_psf"]["mae"] > 0
    for label in ("nominal_psf", "measured_psf"):
        for k, v in cold[label].items():
            assert again[label][k] == pytest.approx(v, rel=1e-6, abs=1e-9)


def test_the_judge_records_captures_with_the_sensor_its_network_was_trained_for(monkeypatch):
    """The network's weights record names its sensor: the judge's captures (and the crosstalk calibration behind
    them) use that noise and, hyperspectral, the response its architecture record holds; records without one
    are the default camera's (its rawtoaces curves, read here from colour-science's file)."""
    import os
    from types import SimpleNamespace

    import doefab.reconstruction.specs as specs
    from colour.characterisation.aces_it import ROOT_RESOURCES_RAWTOACES
    from doefab.imaging.sensor import Sensor

    bands = np.arange(400, 701, 10) * 1e-9
    nikon = Sensor("Nikon D5100", full_well_e=5000.0, read_noise_e=4.0)
    judge = NetworkJudge.__new__(NetworkJudge)
    judge.task, judge.images, judge.size, judge._nominal = "hyperspectral", 2, 64, None
    judge.rec = SimpleNamespace(meta={"arch": {"response": nikon.rgb(bands).tolist()}, "sensor": nikon.record()},
                                pair=SimpleNamespace(wavelengths=bands))
    judge.pair = lambda err, height=None: judge.rec.pair
    seen = {}

    class Stop(Exception):
        pass

    def spy(task, split, indices, size, pair, response=None, noise="default", crosstalk=None, **kw):
        seen.update(response=response, noise=noise, crosstalk=crosstalk)
        raise Stop

    monkeypatch.setattr(specs, "make_batch", spy)
    with pytest.raises(Stop):
        judge.evaluate(PartErrors(crosstalk=(0.05, 0.05)))
    assert np.allclose(seen["response"], nikon.rgb(bands))
    assert (seen["noise"].full_well_e, seen["noise"].read_noise_e) == (5000.0, 4.0)
    calls = []
    import doefab.tolerance.netjudge as nj

    monkeypatch.setattr(nj, "crosstalk_ratios", lambda err, cols, noise: calls.append(noise) or (0, 0, 0, 0))
    seen["crosstalk"](0)
    assert (calls[0].full_well_e, calls[0].read_noise_e) == (5000.0, 4.0)

    judge.rec.meta = {"arch": {}}  # shipped weights recorded before sensors were
    t, noise = judge.sensor()
    data = np.genfromtxt(os.path.join(ROOT_RESOURCES_RAWTOACES, "CANON_EOS_5DMark_II_RGB_Sensitivities.csv"),
                         delimiter=",", names=True)
    canon = np.stack([np.interp(bands * 1e9, data["wavelength"], data[c]) for c in ("R", "G", "B")])
    assert np.allclose(t, canon / canon.sum(axis=1).max(), atol=1e-6)
    assert (noise.full_well_e, noise.read_noise_e) == (25000.0, 3.0)
