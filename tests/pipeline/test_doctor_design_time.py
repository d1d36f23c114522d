"""``doefab doctor`` times the design ``doefab run`` optimises: the same arguments reach ``design.pace.design_time``
and ``doefab.optimize``; a grid whose FFTs fail the memory check is not timed."""

import importlib
from pathlib import Path

import pytest

from doefab.pipeline import doctor
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

REPO = Path(__file__).resolve().parents[2]
pace = importlib.import_module("doefab.design.pace")


def _new_design_scene(tmp_path):
    text = (REPO / "scenes" / "hdr.toml").read_text().replace("n_levels = 16", "n_levels = 8")
    assert "n_levels = 8" in text
    (tmp_path / "s.toml").write_text(text)
    return load_scene(tmp_path / "s.toml")


def test_doctor_times_the_arguments_the_design_stage_optimises(tmp_path, monkeypatch):
    import doefab
    from doefab.pipeline import stages

    scene = _new_design_scene(tmp_path)
    res = resolve(scene)
    assert not res.reuse
    timed, ran = {}, {}
    monkeypatch.setattr(pace, "design_time", lambda **k: timed.update(k) or {
        "seconds": 90.0, "step_s": 1.0, "metric_s": 2.0, "iterations": 60, "evaluations": 4, "grid_px": 3200,
        "device": "cpu"})
    fact = doctor.design_time_fact(res)
    # the scene's own design: its levels, steps, grid and task (read from the scene file by hand)
    assert (timed["task"], timed["n_levels"], timed["iterations"], timed["sampling"]) == ("streak", 8, 60, 1)
    assert timed["camera"].doe_pixels == 3200
    assert fact["value"] == pytest.approx(1.5) and fact["unit"] == "min" and "60 adam steps" in fact["meaning"]

    class Stop(Exception):
        pass

    def fake_optimize(**k):
        ran.update(k)
        raise Stop

    monkeypatch.setattr(doefab, "optimize", fake_optimize)
    with pytest.raises(Stop):
        stages.stage_design(scene, res, tmp_path / "design", quick=False)
    for k in ("out_dir", "progress", "resume"):  # where and how it runs, not what
        ran.pop(k)
    assert ran.keys() == timed.keys() and all(ran[k] is timed[k] or ran[k] == timed[k] for k in ran)


def test_a_grid_beyond_the_fft_memory_limit_is_not_timed(tmp_path, monkeypatch):
    res = resolve(_new_design_scene(tmp_path))
    monkeypatch.setattr(doctor, "FFT_BYTES_LIMIT", 1.0)
    monkeypatch.setattr(pace, "design_time", lambda **k: pytest.fail("timed a grid the memory check refuses"))
    fact = doctor.design_time_fact(res)
    assert fact["value"] != fact["value"] and "not measured" in fact["meaning"]  # nan


def test_the_quick_runs_note_does_not_send_the_user_to_doctor(tmp_path):
    """Doctor times the full run; a --quick run's design is its few coarse steps."""
    from doefab.pipeline.stages import redesign_note

    res = resolve(_new_design_scene(tmp_path))
    full, quick = redesign_note(res, False), redesign_note(res, True)
    assert "doefab doctor measures its run time" in full and "doctor" not in quick
    assert "(60 adam iterations on a 3200² grid" in full and "(10 adam iterations on a 800² grid" in quick
