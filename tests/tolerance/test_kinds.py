"""The tornado judges each error kind alone at one standard deviation of what ``sample_errors`` draws of it: the
part of each kind is compared here with 4000 parts drawn from the shipped budget."""

import math

import numpy as np
import pytest

from doefab.tolerance import study
from doefab.tolerance.errors import load_budget, sample_errors
from doefab.tolerance.kinds import KINDS, kind

N_MASKS = 4

# each kind's entries of a part (one per mask or plate, else one), read from the part's fields independently of
# doefab.tolerance.kinds: a plate's overlay is the length of its 2-D shift
ENTRIES = {
    "etch depth (all plates alike)": lambda p: [d - 1 for d in p.depth_scale],
    "mask overlay": lambda p: [math.hypot(dx, dy) for dx, dy in p.overlay],
    "mask rotation": lambda p: list(p.rotation),
    "edge bias": lambda p: [p.edge_bias],
    "corner rounding": lambda p: [p.corner_rounding],
    "surface roughness": lambda p: [p.roughness],
    "decenter across split": lambda p: [p.mount_shift[0]],
    "decenter along split": lambda p: [p.mount_shift[1]],
    "mount rotation": lambda p: [p.mount_rotation],
    "mount tilt": lambda p: [p.mount_tilt],
    "axial gap": lambda p: [p.axial_gap],
    "axial gap spread": lambda p: [p.axial_gap],
    "crosstalk, uncalibrated": lambda p: list(p.crosstalk),
    "crosstalk, calibrated": lambda p: list(p.crosstalk),
}
CENTRED = {"axial gap spread"}  # drawn about a nominal value: judged at the draws' standard deviation about it
CARRIED = {"corner rounding", "surface roughness", "axial gap"}  # every part carries its mean: judged at that


@pytest.fixture(scope="module")
def drawn():
    budget = load_budget()
    rng = np.random.default_rng(38)
    parts = [sample_errors(budget, rng, seed=i, n_masks=N_MASKS) for i in range(4000)]
    return budget, {name: np.array([f(p) for p in parts]) for name, f in ENTRIES.items()}


def test_every_kind_sits_at_one_standard_deviation_of_the_draws(drawn):
    budget, values = drawn
    assert {k.name for k in KINDS} == set(ENTRIES)
    for k in KINDS:
        v = values[k.name]
        part = np.array(ENTRIES[k.name](k.budget_part(budget, N_MASKS)))
        if k.name.startswith("crosstalk"):  # the budget's sensor, the same in every part, for its own pipeline
            assert np.all(v == v[0]) and np.all(part == v[0]), k.name
            continue
        if k.name in CARRIED:
            want, got = float(v.mean()), float(np.sqrt(np.mean(part ** 2)))
        elif k.name in CENTRED:
            base = np.array(ENTRIES[k.name](k.base_part(budget)))
            want, got = float(v.std()), float(np.sqrt(np.mean((part - base) ** 2)))
            # measured from the draws' centre (within 4 standard errors of their mean)
            assert base == pytest.approx(v.mean(), abs=4 * float(v.std()) / math.sqrt(len(v))), k.name
        else:  # errors drawn about the error-free part: the rms of the drawn entries
            want, got = float(np.sqrt(np.mean(v ** 2))), float(np.sqrt(np.mean(part ** 2)))
        assert want > 0, k.name
        assert got == pytest.approx(want, rel=0.04), k.name
        assert k.from_budget(budget) == pytest.approx(want, rel=0.04), k.name  # the value the tornado prints


def test_the_overlay_is_judged_at_the_rms_length_of_a_plate_shift(drawn):
    """0.5 µm per axis is a 2-D shift of rms length √2 × 0.5 µm, and the tornado's label says which it is."""
    budget, values = drawn
    lengths = values["mask overlay"]
    assert float(np.sqrt(np.mean(lengths ** 2))) == pytest.approx(math.sqrt(2) * 0.5e-6, rel=0.02)
    k = kind("mask overlay")
    assert f"{k.from_budget(budget) / k.si:.3g} {k.unit}" == "0.707 µm rms length"


def test_the_tornado_measures_a_spread_from_its_centre(monkeypatch):
    """The gap's spread is the change from the nominal-gap part to the part one sigma beyond it; the nominal gap
    every part carries is a row of its own, from the error-free part (a metric of -1000 × the gap in metres
    stands in for the judge)."""

    class Judge:
        n_masks = N_MASKS
        nominal = None

        def score(self, psf):
            return {"metric": 0.0}

    monkeypatch.setattr(study, "judge_for", lambda design_dir, s=1: Judge())
    monkeypatch.setattr(study, "evaluate_part",
                        lambda d, s, e, networks=False, w=None: {"metric": -1e3 * e["axial_gap"]})
    budget = load_budget()
    rows = {r["error"]: r for r in study.tornado_rows("x", budget, [kind("axial gap"), kind("axial gap spread")], {},
                                                      False, None, False)}
    nominal_mm = budget["mounting"]["axial_gap_mm"] + budget["mounting"]["pupil_behind_glass_mm"]
    sigma_mm = budget["mounting"]["axial_gap_sigma_mm"]
    assert rows["axial gap spread"]["value"] == pytest.approx(sigma_mm)
    assert rows["axial gap spread"]["delta"] == pytest.approx(-sigma_mm)
    assert rows["axial gap"]["value"] == pytest.approx(nominal_mm)
    assert rows["axial gap"]["delta"] == pytest.approx(-nominal_mm)
    assert "axial gap spread" not in study.sweep_names()  # its magnitudes are the axial gap's sweep
