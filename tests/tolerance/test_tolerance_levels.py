"""Tolerance studies of a design made for another number of levels: its relief has log2 L masks, each with its own
errors, and every study (judge, error kinds, Monte Carlo, surrogate, quantization) follows the design's M."""

import numpy as np
import pytest
import torch

import doefab
from doefab.design.design import Design
from doefab.errors import DoefabError
from doefab.tolerance import montecarlo, study
from doefab.tolerance.errors import PartErrors, load_budget, sample_errors
from doefab.tolerance.kinds import KINDS
from doefab.tolerance.surrogate import fit_surrogate, parameters


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory):
    """An 8-level streak design (a staircase in the coded half) on a 100-pixel grid."""
    root = tmp_path_factory.mktemp("tol8")
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    lv = np.tile((np.arange(100) % 8).astype(np.uint8), (100, 1))
    lv[:, 50:] = 7  # plain half
    d = Design(task="streak", task_params={"kernel_size": 31, "arm_px": 8}, camera=cam, wavelengths=(550e-9,),
               depths=(5.0,), height=doefab.levels_to_height(lv, cam, 8), levels=lv, n_levels=8,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d.save(root / "design")
    return root / "design"


def test_the_judge_has_three_masks_and_their_depths_scale_the_eight_level_relief(design_dir):
    """Every mask etched α times too deep is the height map (L − 1)·d − α·(L − 1 − level)·d: the relief model's PSF
    equals the PSF of that explicit height map (an independent route through the judge)."""
    j = study.judge_for(str(design_dir), 1)
    assert j.n_masks == 3 and j.chain == {1: 0, 2: 0, 3: 0}
    d8 = 550e-9 / (float(j.design.camera.material.index(550e-9)) - 1) / 8
    assert j.step == pytest.approx(d8, rel=1e-12)
    lv = j.design.levels.astype(np.float64)
    for alpha in (1.0, 1.06):
        with torch.no_grad():
            got = j.psfs(PartErrors(depth_scale=(alpha,) * 3))["coded"].double()
        want = j.psf_from_height(7 * d8 - alpha * (7 - lv) * d8)
        assert float((got - want).abs().max()) < 1e-5 * float(want.max())
    with pytest.raises(DoefabError, match="this design has 3 masks"):
        j.evaluate(PartErrors(depth_scale=(1.0,) * 4))


def test_every_kind_and_sampled_part_follows_the_design_masks(design_dir, tmp_path):
    budget = load_budget()
    j = study.judge_for(str(design_dir), 1)
    for k in KINDS:
        part = k.budget_part(budget, 3)
        assert all(len(getattr(part, f)) in (0, 3) for f in ("depth_scale", "overlay", "rotation")), k.name
        assert np.isfinite(j.evaluate(part)["metric"])
    part = sample_errors(budget, np.random.default_rng(0), n_masks=3)
    assert len(part.depth_scale) == len(part.overlay) == len(part.rotation) == 3
    four = sample_errors(budget, np.random.default_rng(0), n_masks=4)  # one stream: the etch depths come first
    assert four.depth_scale[:3] == part.depth_scale and len(four.depth_scale) == 4
    rows = montecarlo.monte_carlo(design_dir, budget, 2, tmp_path / "mc", seed=3, progress=False)
    assert [len(r["errors"]["depth_scale"]) for r in rows] == [3, 3]
    names = [p[0] for p in parameters(budget, j.chain, 3)]
    assert "etch depth, mask 3" in names and not any(n.endswith("mask 4") for n in names)
    model = fit_surrogate(lambda p: j.evaluate(p)["metric"], budget, j.chain, False, n_masks=3)
    assert model["names"] == names  # ±h for each, and the points its judged curves add (3 of theirs are ±h and 0)
    assert model["parts"] == 2 * len(names) + 1 + sum(len(c["u"]) - 3 for c in model["curves"].values())


def test_quantization_study_starts_at_the_design_levels(design_dir):
    rows = study.quantization_study(design_dir)
    assert [r["levels"] for r in rows] == ["continuous", 8, 4, 2]
    assert rows[1]["source"] == "the committed 8-level map" and rows[1]["l1_to_nominal"] < 1e-9


def test_each_kind_is_judged_at_one_standard_deviation_of_the_parts_the_budget_draws():
    """The tornado and "limited by" compare errors at one probability point: each kind's magnitude is the standard
    deviation of that error over parts drawn from the budget (decenter is uniform, the etch depth has a systematic
    and a random part), measured here on 4000 drawn parts."""
    budget = load_budget()
    rng = np.random.default_rng(11)
    parts = [sample_errors(budget, rng, n_masks=4) for _ in range(4000)]
    drawn = {"etch depth (all plates alike)": [p.depth_scale[0] - 1 for p in parts],
             "mask rotation": [p.rotation[2] for p in parts],
             "edge bias": [p.edge_bias for p in parts],
             "decenter across split": [p.mount_shift[0] for p in parts],
             "decenter along split": [p.mount_shift[1] for p in parts],
             "mount rotation": [p.mount_rotation for p in parts]}
    by_name = {k.name: k for k in KINDS}
    for name, values in drawn.items():
        sigma = float(np.std(values))
        assert sigma > 0, name
        assert by_name[name].from_budget(budget) == pytest.approx(sigma, rel=0.05), name
