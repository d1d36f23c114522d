"""The tolerance stage hands the scene's sensor noise to the study, so that the PSF-level judge's crosstalk
calibration draws it (the network-level judge uses its network's sensor); the default sensor changes nothing."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from doefab.pipeline import stages
from doefab.pipeline.scene import load_scene
from doefab.tolerance.errors import sample_errors

REPO = Path(__file__).resolve().parents[2]


class _Stop(Exception):
    pass


def _budget_the_study_gets(tmp_path, monkeypatch, sensor: str) -> dict:
    import doefab.tolerance.report as report

    p = tmp_path / "hdr.toml"
    p.write_text((REPO / "scenes" / "hdr.toml").read_text() + f"\n[sensor]\n{sensor}\n")
    seen = {}

    def spy(design_dir, budget, out, **kw):
        seen["budget"] = budget
        raise _Stop

    monkeypatch.setattr(report, "run_study", spy)
    with pytest.raises(_Stop):
        stages.stage_tolerance(load_scene(p), SimpleNamespace(reuse=True, sensor=None), tmp_path / "run" / "tolerance", True)
    return seen["budget"]


def test_the_studys_parts_carry_the_scenes_sensor_noise(tmp_path, monkeypatch):
    budget = _budget_the_study_gets(tmp_path, monkeypatch, "full_well_e = 900.0\nread_noise_e = 7.0")
    part = sample_errors(budget, np.random.default_rng(0), n_masks=4)
    assert (part.full_well_e, part.read_noise_e) == (900.0, 7.0)


def test_the_default_sensor_stated_leaves_the_budget_as_it_was(tmp_path, monkeypatch):
    budget = _budget_the_study_gets(tmp_path, monkeypatch, "full_well_e = 25000.0\nread_noise_e = 3.0")
    assert not {"full_well_e", "read_noise_e"} & set(budget["sensor"])
    part = sample_errors(budget, np.random.default_rng(0), n_masks=4)
    assert (part.full_well_e, part.read_noise_e) == (25_000.0, 3.0)
