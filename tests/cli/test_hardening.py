"""One test per defect the hardening issue lists (the wrong-input catalogue is test_error_catalogue.py)."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest
import torch

import doefab
from doefab.cli import main
from doefab.errors import DoefabError
from doefab.io import MARKER, atomic_write_bytes, staging_dir


def test_lbfgs_runs_its_whole_budget(tiny_camera, tiny_streak):
    d = doefab.optimize("streak", iterations=20, optimizer="lbfgs", camera=tiny_camera, progress=False,
                        task_params=tiny_streak, qat_fraction=0.25)
    assert d.extra["evaluations"] == 20 and "stop_reason" not in d.extra
    assert [r[0] for r in d.history] == list(range(20))
    assert min(r[2] for r in d.history) < d.history[0][2] - 0.05


def test_nlopt_without_progress_is_an_error_not_a_result():
    from doefab.design.nloptrun import run_nlopt

    theta = torch.zeros(4, 4, requires_grad=True)
    rec = []
    with pytest.raises(DoefabError, match="without lowering the loss"):
        run_nlopt("lbfgs", theta, lambda step: (theta * 0).sum() + 1.0, lambda s, v: rec.append(v), 0, 10, 10,
                  torch.ones(4, 4))
    assert len(rec) < 10


def test_nlopt_refuses_more_variables_than_it_can_take():
    from doefab.design.nloptrun import run_nlopt

    theta = torch.zeros(1500, 1500, requires_grad=True)
    with pytest.raises(DoefabError, match="--sampling 2"):
        run_nlopt("lbfgs", theta, None, None, 0, 10, 10, torch.ones(1500, 1500))


def test_resume_may_extend_iterations(tiny_camera, tiny_streak, tmp_path):
    kw = dict(camera=tiny_camera, progress=False, task_params=tiny_streak, checkpoint_every=2, batch=0, lr=0.05,
              qat_fraction=0.0)
    doefab.optimize("streak", iterations=4, out_dir=tmp_path, **kw)
    d = doefab.optimize("streak", iterations=7, out_dir=tmp_path, resume=True, **kw)
    assert [r[0] for r in d.history] == list(range(7))


def test_ctrl_c_exits_130_keeps_the_checkpoint_and_says_how_to_resume(tmp_path, capsys, monkeypatch):
    def interrupted(*a, out_dir=None, **k):
        (out_dir / "checkpoint.pt").write_bytes(b"x")
        raise KeyboardInterrupt

    monkeypatch.setattr(doefab, "optimize", interrupted)
    assert main(["design", "--task", "streak", "--out", str(tmp_path / "d")]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted" in err[0] and "--resume" in err[0]
    assert (tmp_path / "d" / "checkpoint.pt").is_file()


def test_ctrl_c_before_a_checkpoint_leaves_nothing(tmp_path, capsys, monkeypatch):
    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(doefab, "optimize", interrupted)
    assert main(["design", "--task", "streak", "--out", str(tmp_path / "a" / "d")]) == 130
    assert list(tmp_path.iterdir()) == []


def test_a_bug_is_one_line_exit_1_and_debug_shows_the_traceback(tmp_path, capsys, monkeypatch):
    def bug(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(doefab, "optimize", bug)
    assert main(["design", "--task", "streak", "--out", str(tmp_path / "d")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "internal error" in err and "--debug" in err
    assert not (tmp_path / "d").exists()
    assert main(["design", "--task", "streak", "--out", str(tmp_path / "d"), "--debug"]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_stale_staging_folders_of_killed_runs_are_removed(tmp_path):
    dead = tmp_path / ".m.staging.999999999.abcd"  # no such process
    dead.mkdir()
    (dead / "big.gds").write_bytes(b"0" * 1000)
    live = tmp_path / f".m.staging.{os.getppid()}.efgh"  # a running process: left alone
    live.mkdir()
    with staging_dir(tmp_path / "m") as stage:
        (stage / "f").write_text("ok")
    assert not dead.exists() and live.exists()
    assert (tmp_path / "m" / "f").read_text() == "ok"


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_files_and_folders_respect_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        atomic_write_bytes(tmp_path / "a" / "f.bin", b"x")
        with staging_dir(tmp_path / "s") as stage:
            atomic_write_bytes(stage / "g.bin", b"y")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a" / "f.bin").stat().st_mode) == 0o666 & ~umask
    assert stat.S_IMODE((tmp_path / "s").stat().st_mode) == 0o777 & ~umask
    assert stat.S_IMODE((tmp_path / "s" / "g.bin").stat().st_mode) == 0o666 & ~umask


def test_force_replaces_only_own_output_and_marker_is_written(tmp_path, capsys):
    out = tmp_path / "p"
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)]) == 0
    assert (out / MARKER).is_file()
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out), "--force"]) == 0


def test_holder_that_fails_a_check_leaves_nothing_printable(tmp_path, monkeypatch):
    import holder_cad.build as build
    from holder_cad.build import HolderCheckError, write_holder
    from holder_cad.params import HolderParams

    real = build.run_checks

    def failing_gap(parts, asm, p, expected_bodies):
        out = real(parts, asm, p, expected_bodies)
        if asm:
            out["passed"] = False
            out["fit_failures"] = ["die_to_pocket_gap_mm = 0.000 (needs ≥ 0.25)"]
            out["failing"] = out["fit_failures"]
        return out

    monkeypatch.setattr(build, "run_checks", failing_gap)
    with pytest.raises(HolderCheckError, match="die_to_pocket_gap_mm"):
        write_holder(HolderParams(), tmp_path, step=False, renders=False)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != ".doefab-output.json") == ["holder.FAILED.json"]


def test_holder_checks_measure_the_doe_distance_on_the_mesh():
    from holder_cad.build import assembly, build_parts
    from holder_cad.checks import run_checks
    from holder_cad.params import HolderParams

    p = HolderParams(washer_recess_mm=1.5, thread_length_mm=2.0)
    parts = build_parts(p)
    c = run_checks(parts, assembly(parts, p), p, expected_bodies=2)
    # independent of the formula: the face sits washer_recess_mm above the lens-side end of the assembly
    assert c["doe_face_above_lens_side_end_mm"] == pytest.approx(1.5, abs=1e-3)
    assert c["doe_to_lens_mm"] == pytest.approx(3.5 - 2.0 + 1.5, abs=1e-3)
    assert {b["quantity"] for b in c["fit_bounds"]} >= {"doe_to_lens_mm", "thread_engagement_turns",
                                                        "die_to_pocket_clearance_mm", "wall_mm"}


def test_unit_hint_when_followed_is_accepted():
    from doefab.cli._args import wavelength_nm

    with pytest.raises(Exception, match="write 550"):
        wavelength_nm("5.5e-07")
    assert wavelength_nm("550") == 550.0


def test_figures_label_infinity_and_share_one_scale(tmp_path):
    from doefab.plotting import depth_label, psf_pair_figure

    assert depth_label(float("inf")) == "z = ∞" and depth_label(2.0) == "z = 2 m"
    c = np.zeros((1, 1, 63, 63))
    c[0, 0, 31, 31] = 0.5
    u = c * 0.1
    psf_pair_figure(tmp_path / "f.png", c, u, [float("inf")], 5.4e-6)
    assert (tmp_path / "f.png").stat().st_size > 1000
