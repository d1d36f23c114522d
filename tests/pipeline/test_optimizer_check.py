"""A scene asking nlopt (``design.optimizer`` lbfgs or mma) to optimise more coded pixels than nlopt takes is refused
by doctor and run alike, naming a design grid that fits; the count is the half disc's, and the limit the one the
design stage's nlopt driver enforces."""

import math
from pathlib import Path

import pytest
import torch

from doefab.design.nloptrun import NLOPT_MAX_VARIABLES, run_nlopt
from doefab.design.optimize import coded_mask, design_camera
from doefab.errors import DoefabError
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

REPO = Path(__file__).resolve().parents[2]


def _scene(tmp_path, **lines):
    text = (REPO / "scenes" / "hdr.toml").read_text()  # 3200² DOE pixels, sampling 1
    for old, new in lines.items():
        assert old in text
        text = text.replace(old, new)
    (tmp_path / "s.toml").write_text(text)
    return load_scene(tmp_path / "s.toml")


@pytest.mark.parametrize("opt", ["lbfgs", "mma"])
def test_nlopt_on_the_full_hdr_grid_is_refused_naming_sampling_2_which_passes(tmp_path, opt):
    with pytest.raises(DoefabError) as exc:
        resolve(_scene(tmp_path, **{'optimizer = "adam"': f'optimizer = "{opt}"'}))
    msg = str(exc.value)
    assert f"design.optimizer {opt}" in msg and 'design.sampling = 2 or design.optimizer = "adam"' in msg
    n = int(msg.split(" has ")[1].split(" coded")[0].replace(",", ""))
    assert n == pytest.approx(math.pi * 1600 ** 2 / 2, rel=2e-3)  # a half disc 3200 px across
    res = resolve(_scene(tmp_path, **{'optimizer = "adam"': f'optimizer = "{opt}"', "sampling = 1": "sampling = 2"}))
    assert res.settings["sampling"] == 2 and res.settings["optimizer"] == opt


def test_the_design_stage_refuses_the_same_count():
    """The oracle: the nlopt driver itself refuses the full grid's coded pixels before any evaluation, and the
    half grid's count is within its limit."""
    cam = resolve(load_scene(REPO / "scenes" / "hdr.toml")).camera
    full = coded_mask(cam)
    with pytest.raises(DoefabError, match="nlopt's optimisers take at most"):
        run_nlopt("lbfgs", torch.zeros(full.shape), None, None, 0, 1, 1, full)
    assert int(coded_mask(design_camera(cam, 2)).sum()) <= NLOPT_MAX_VARIABLES < int(full.sum())


def test_adam_and_a_radial_profile_are_not_limited(tmp_path):
    assert resolve(_scene(tmp_path)).settings["optimizer"] == "adam"
    res = resolve(_scene(tmp_path, **{'optimizer = "adam"': 'optimizer = "lbfgs"',
                                      "[design]": '[design]\nparameterization = "radial"'}))
    assert res.settings["parameterization"] == "radial"


def test_no_fix_sends_the_scene_back_and_forth_between_nlopt_and_the_grid_checks(tmp_path):
    """A 851 px window on the HDR camera: the alias-free field reaches λ·s/(2p) = 486 nm · 50 mm / (2 · 2.7 µm) =
    833 sensor px (5.4 µm) from the axis on the full grid and 417 on the half grid, and the window needs 426. On the
    full grid nlopt is refused and no coarser grid holds the window: Adam alone is named, and it passes. From a 4×
    grid (too coarse for the window, though nlopt would take it) the grid that holds it is named with Adam."""
    reach = {f: 486e-9 * 0.05 / (2 * 2.7e-6 * f) / 5.4e-6 for f in (1, 2)}
    assert reach[1] > 851 / 2 + 0.5 > reach[2]
    lines = {'optimizer = "adam"': 'optimizer = "lbfgs"', "kernel_px = 95": "kernel_px = 851"}
    with pytest.raises(DoefabError) as exc:
        resolve(_scene(tmp_path, **lines))
    assert 'set design.optimizer = "adam"' in str(exc.value) and "design.sampling =" not in str(exc.value)
    assert resolve(_scene(tmp_path, **{"kernel_px = 95": "kernel_px = 851"})).settings["optimizer"] == "adam"
    with pytest.raises(DoefabError) as exc:
        resolve(_scene(tmp_path, **lines, **{"sampling = 1": "sampling = 4"}))
    assert "1 problem" in str(exc.value) and "nlopt" not in str(exc.value)  # the 4× grid is nlopt's to take
    assert 'set design.sampling = 1 with design.optimizer = "adam"' in str(exc.value)
