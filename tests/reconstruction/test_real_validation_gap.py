"""The depth gap's interval on the measured-data page (``benchmarks/real_validation.py``): a bootstrap whose
draws can be counted by hand."""

import pytest


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


def _exact(real, test, groups):
    """{gap: probability} of the bootstrap's gap, enumerated: every draw of the scenes (all crops of each) and of
    the test values, each equally likely."""
    import itertools
    from collections import defaultdict
    from fractions import Fraction

    scenes = sorted(set(groups))
    crops = {g: [v for v, h in zip(real, groups) if h == g] for g in scenes}
    out = defaultdict(Fraction)
    n_r, n_t = len(scenes) ** len(scenes), len(test) ** len(test)
    for pick in itertools.product(scenes, repeat=len(scenes)):
        vals = [v for g in pick for v in crops[g]]
        for t in itertools.product(test, repeat=len(test)):
            gap = round(sum(vals) / len(vals) - sum(t) / len(t), 9)
            out[gap] += Fraction(1, n_r * n_t)
    return out


def test_the_draws_follow_the_enumerated_bootstrap(rv):
    """Unequal scenes (one crop of 0, two crops 0.2 and 1) and varied test values: the share of draws at each gap
    matches the enumerated distribution (20 000 draws: a share's standard error ≤ 0.0036)."""
    import numpy as np

    real, groups, test = [0.0, 0.2, 1.0], ["a", "b", "b"], [0.0, 0.3, 0.9]
    want = _exact(real, test, groups)
    draws = np.round(rv.gap_draws(real, test, groups, draws=20000, seed=3), 9)
    assert set(np.unique(draws)) <= set(want)
    for gap, p in want.items():
        assert abs(np.mean(draws == gap) - float(p)) < 0.015, (gap, float(p))


def test_the_named_sources_are_the_scenes_the_evaluation_draws(rv, monkeypatch):
    """``depth_sources`` names, for each measured scene index, the scene ``specs.depth_scene`` crops for the
    evaluation's scene of that index (its generator ``sample_rng("real", i)``), recorded as it draws."""
    from types import SimpleNamespace

    from doefab.reconstruction import realdata
    from doefab.reconstruction.data import sample_rng
    from doefab.reconstruction.specs import depth_scene

    n = 6
    named = rv.depth_sources(n)
    drawn, original = [], realdata.drawn_depth_scene

    def spy(rng):
        drawn.append(original(rng))
        return drawn[-1]

    monkeypatch.setattr(realdata, "drawn_depth_scene", spy)
    for i in range(n):
        depth_scene("real", i, sample_rng("real", i), 96, SimpleNamespace(depths=(1.0, 2.0, 5.0)))
    names = [s[0] for s in realdata.depth_scenes()]
    assert [names[k] for k in drawn] == named and len(set(named)) > 1


def test_an_evaluation_with_a_scene_without_highlights_still_makes_its_paired_interval(tables, tmp_path):
    """An HDR evaluation whose scene has no highlight gives NaN there, written "nan" in strict JSON
    (``atomic_write_json``); the tables read it back as a number and leave that scene out of the paired interval."""
    from doefab.io import atomic_write_json

    per = {"proposed": [{"psnr_highlight": v} for v in (30.0, float("nan"), 31.0, 29.0)],
           "uncoded_only": [{"psnr_highlight": v} for v in (27.0, float("nan"), 27.5, 26.0)]}
    atomic_write_json(tmp_path / "hdr" / "metrics.json", {"per_scene": per})
    back = tables._load(tmp_path, "hdr")["per_scene"]
    text = tables._paired(back, "uncoded_only", "psnr_highlight", 1.0, "dB", None, None)
    # by hand over the three scenes with highlights: differences 3, 3.5, 3; mean 3.17, sd 0.289, t(0.975, 2) 4.303
    assert text == "+3.17 dB (+2.45 to +3.88); proposed better on 3 of 3 scenes", text
