"""The grid study's bound is on the whole design's metric, not only on the block it is measured on."""

import numpy as np
import pytest

import doefab
from doefab.design.design import Design
from doefab.tasks.grating import GratingTask
from doefab.tolerance.errors import load_budget
from doefab.tolerance.grid import grid_study
from doefab.tolerance.judge import PSFJudge
from doefab.tolerance.kinds import kind

N, BLOCK = 128, 32


@pytest.fixture(scope="module")
def design():
    """A quantized blazed grating (32-pixel period, 3 bands) over the coded half of a 128-pixel aperture."""
    pitch = 5.4e-6
    cam = doefab.Camera(aperture_diameter=N * pitch, doe_pitch=pitch, doe_pixels=N, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    task = GratingTask(kernel_size=81, n_bands=3, period_pixels=32.0)
    task.bind(cam)
    lv = doefab.quantize_levels(task.init_height(cam, np.random.default_rng(0)), cam)
    lv[:, N // 2:] = 15
    return Design(task="grating", task_params=task.params(), camera=cam, wavelengths=task.wavelengths(cam),
                  depths=(5.0,), height=doefab.levels_to_height(lv, cam), levels=lv,
                  metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})


@pytest.fixture(scope="module")
def overlay_only():
    budget = load_budget()
    return {**budget, "overlay": {**budget["overlay"], "rotation_sigma_urad": 0.0},
            "lithography": {"edge_bias_sigma_um": 0.0, "corner_rounding_um": 0.0},
            "surface": {**budget["surface"], "roughness_rms_nm": 0.0},
            "mounting": {**budget["mounting"], "rotation_sigma_deg": 0.0}}


def test_the_bound_covers_the_whole_design_where_the_block_understates_it(design, overlay_only):
    """The whole design's own metric differs between the 1× and 2× grids by more than the 32² block's PSFs say
    (the block's broader PSF puts less of everything in the metric pixels); the study's bound for 1× covers that
    difference, and a tolerance below it does not leave the study on 1×."""
    part = kind("mask overlay").budget_part(overlay_only, 4)
    m1, m2 = (PSFJudge(design, s).evaluate(part)["metric"] for s in (1, 2))
    full_1_2 = abs(m1 - m2)
    rec = grid_study(PSFJudge(design, 1), overlay_only, block=BLOCK, tolerance=full_1_2 / 2)
    assert list(rec["kinds"]) == ["mask overlay"]
    v = rec["kinds"]["mask overlay"]
    assert v["block_bound"][1] < full_1_2 / 2  # the block alone would understate it, and choose 1×
    assert v["bound"][1] >= full_1_2
    assert all(s >= 1 for s in rec["block_to_full"])
    assert v["grid"] > 1 and rec["monte_carlo_grid"] > 1
