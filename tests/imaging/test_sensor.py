"""The sensor as a scene or a weights record names it: response and noise."""

import math

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.imaging.sensor import Sensor, sensor_from_record


def test_the_noise_has_the_poisson_gaussian_variance():
    """A flat capture at 25 % of full scale: variance x / N_fw + (σ_read / N_fw)² (shot + read, in units of the
    full well), measured on 400 000 pixels."""
    s = Sensor(full_well_e=1000.0, read_noise_e=10.0)
    x = np.full((400, 1000), 0.25)
    got = s.noise().apply(x, np.random.default_rng(1))
    want = 0.25 / 1000 + (10 / 1000) ** 2
    assert got.mean() == pytest.approx(0.25, abs=1e-4)
    assert got.var() == pytest.approx(want, rel=0.02)


def test_what_differs_between_sensors():
    default = Sensor().record()
    assert Sensor().differs_from(None, spectral=True) == [] and Sensor().differs_from({}, spectral=True) == []
    assert sensor_from_record(None) == Sensor() and sensor_from_record({"x": 1}) == Sensor()
    assert sensor_from_record({"full_well_e": 9000.0, "read_noise_e": 2.0}) == Sensor(full_well_e=9000.0,
                                                                                       read_noise_e=2.0)
    # a record of an RGB task's sensor holds its noise only; its response is nobody's business
    assert Sensor(read_noise_e=12.0).record(with_response=False) == {"full_well_e": 25000.0, "read_noise_e": 12.0}
    assert Sensor("Nikon D5100").differs_from(Sensor().record(with_response=False), spectral=True)[0].startswith(
        "response Canon EOS 5D Mark II")
    noisy = Sensor(read_noise_e=12.0)
    diff = noisy.differs_from(default, spectral=False)
    assert len(diff) == 1 and "read_noise_e 3 (this camera: 12)" in diff[0]
    nikon = Sensor("Nikon D5100")
    assert nikon.differs_from(default, spectral=False) == []  # RGB scenes: the response forms nothing
    assert nikon.differs_from(default, spectral=True)[0].startswith("response Canon EOS 5D Mark II")
    assert not nikon.has_default_response() and Sensor().has_default_response()
    # records name a sensor only when it is not the default one, in what the task uses
    assert Sensor().entry(True) == {} and nikon.entry(False) == {}
    assert nikon.entry(True)["sensor"]["response"] == "Nikon D5100"
    assert noisy.entry(False) == {"sensor": {"full_well_e": 25000.0, "read_noise_e": 12.0}}


def test_a_sensor_is_refused_whole_before_any_work(tmp_path):
    with pytest.raises(DoefabError, match="full_well_e"):
        Sensor(full_well_e=math.nan)
    with pytest.raises(DoefabError, match="read_noise_e"):
        Sensor(read_noise_e=-1.0)
    with pytest.raises(DoefabError, match="full_well_e must be ≥ 100"):
        Sensor(full_well_e=1e12)
    with pytest.raises(DoefabError, match="neither a known camera"):
        Sensor(response=str(tmp_path / "missing.csv"))
