"""``doefab doctor`` checks exactly what ``doefab run`` and ``run --quick`` will do with a scene's design grid:
a ``design.sampling`` that does not divide the DOE grid is refused by the doctor (not first by the design stage),
and ``--quick`` coarsens the grid only by a factor that divides it (a sweep of lenses, apertures and pitches)."""

import itertools
import math

import pytest

from doefab.design.optimize import _design_camera
from doefab.errors import DoefabError
from doefab.pipeline.scene import load_scene
from doefab.pipeline.stages import _design_run, quick_sampling
from doefab.pipeline.system import resolve


def _scene(tmp_path, focal_mm, f_number, pitch_um, sampling=None):
    design = "" if sampling is None else f"[design]\nsampling = {sampling}\n"
    p = tmp_path / f"s_{focal_mm}_{f_number}_{pitch_um}_{sampling}.toml"
    p.write_text(f'task = "hdr"\nstages = ["design"]\n[camera]\nfocal_length_mm = {focal_mm}\nf_number = {f_number}\n'
                 f"doe_pitch_um = {pitch_um}\n{design}")
    return load_scene(p)


def _grid(focal_mm, f_number, pitch_um, focus_m=5.0):
    """The DOE grid the scene implies, computed here: the aperture over the pitch, rounded up to even."""
    s = 1 / (1 / (focal_mm * 1e-3) - 1 / focus_m)
    aperture = 1 / (1 / s + 1 / focus_m) / f_number
    return 2 * math.ceil(aperture / (pitch_um * 1e-6) / 2 - 1e-9)


SWEEP = list(itertools.product((25.0, 35.0, 50.0), (2.8, 4.0, 5.6), (4.0, 5.4, 8.0), (None, 3, 4)))


@pytest.mark.parametrize("focal_mm,f_number,pitch_um,sampling", SWEEP)
def test_doctor_refuses_what_the_design_stage_would(tmp_path, focal_mm, f_number, pitch_um, sampling):
    scene = _scene(tmp_path, focal_mm, f_number, pitch_um, sampling)
    grid = _grid(focal_mm, f_number, pitch_um)
    divides = sampling is None or grid % sampling == 0  # the hdr design's own sampling (2) divides any even grid
    try:
        res = resolve(scene)
    except DoefabError as exc:
        assert ("must divide the DOE grid" in str(exc)) == (not divides), str(exc)
        if not divides:
            assert f"({grid} px)" in str(exc) and "design.sampling" in str(exc)
        return
    assert divides, f"doctor passed sampling {sampling} on a {grid}-px grid"
    assert res["camera"].doe_pixels == grid
    for quick in (False, True):  # what the design stage hands the optimiser, run and run --quick
        iters, used = _design_run(res["settings"], quick)
        cam = _design_camera(res["camera"], used)  # the optimiser's own check: raises if it does not divide
        assert cam.doe_pixels * used == grid


def test_quick_sampling_picks_a_factor_that_divides():
    assert quick_sampling(3200, 1) == 4 and quick_sampling(3200, 2) == 4
    assert quick_sampling(2234, 1) == 2  # 2234 = 2 · 1117: 4 would not divide it
    assert quick_sampling(2190, 1) == 5 and quick_sampling(2190, 2) == 6  # 2190 = 2 · 3 · 5 · 73; ties: larger
    assert quick_sampling(2188, 2) == 4
    assert quick_sampling(1000, 3) == 3  # nothing in 3..8 that divides 1000 and is a multiple of 3
    for grid in range(100, 3000, 2):
        for s in (1, 2, 4):
            q = quick_sampling(grid, s)
            assert grid % q == 0 and q % s == 0 and q <= max(8, s)


def test_issue_camera_doctor_and_quick_run_agree(tmp_path):
    """The trial's lens: 25 mm f/2.8 with a 4 µm DOE pitch gives a 2234-px grid; doctor names the sampling a
    scene sets when it cannot divide it, and the quick run's coarsening divides it."""
    grid = _grid(25.0, 2.8, 4.0)
    assert grid == 2234
    with pytest.raises(DoefabError, match=r"design.sampling 4 must divide the DOE grid \(2234 px\): use 1 or 2"):
        resolve(_scene(tmp_path, 25.0, 2.8, 4.0, 4))
    res = resolve(_scene(tmp_path, 25.0, 2.8, 4.0))
    assert _design_run(res["settings"], True)[1] == 2
