"""Exit statuses (``cli._exits``): Ctrl-C is 130 and keeps a checkpoint, a bug is one line and exit 1."""

import doefab
from doefab.cli import main


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


def test_an_interrupted_force_run_leaves_no_earlier_result_and_says_to_resume_in_place_of_force(tmp_path, capsys,
                                                                                                monkeypatch):
    """design --force: the earlier design's files go as the run starts, after every check (a refused --force
    run keeps them), so an interrupt leaves only the new run's checkpoint (no design.json of the old settings that
    masks would be made from) and a user's own file; the hint names --resume in place of --force (repeating
    --force would start afresh again)."""
    import torch

    from doefab.design.optimize import DesignRun

    def interrupted(self, progress=True):
        torch.save({"config": "{}"}, self.ckpt)  # a doefab checkpoint's header
        raise KeyboardInterrupt

    monkeypatch.setattr(DesignRun, "run", interrupted)
    out, argv = tmp_path / "d", ["design", "--task", "streak", "--sampling", "16", "--iterations", "2"]
    assert main([*argv, "--out", str(out)]) == 130
    capsys.readouterr()
    earlier = ("design.json", "levels.npy", "height.npy", "levels.png", "psf_target_vs_design.png")
    for f in (*earlier, "my_photo.png"):  # as a finished earlier run left them, and a file of the user's
        (out / f).write_bytes(b"earlier")
    assert main([*argv, "--optimizer", "mma", "--sampling", "1", "--out", str(out), "--force"]) == 2  # refused
    assert all((out / f).read_bytes() == b"earlier" for f in earlier)
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--force"]) == 130
    err = capsys.readouterr().err
    assert "rerun the same command with --resume in place of --force to continue" in err
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["checkpoint.pt", "my_photo.png"]

    def set_up_only(*a, **k):
        raise KeyboardInterrupt  # in the run's set-up: the earlier checkpoint as it was

    import importlib

    monkeypatch.setattr(importlib.import_module("doefab.design.optimize"), "prepare_run", set_up_only)
    kept = (out / "checkpoint.pt").read_bytes()
    assert main([*argv, "--out", str(out), "--force"]) == 130
    err = capsys.readouterr().err
    assert f"the earlier run's checkpoint in {out} is kept, untouched" in err and (out / "checkpoint.pt").read_bytes(
        ) == kept, err


def test_tolerance_resume_of_a_folder_without_a_study_is_refused(tmp_path, capsys):
    from doefab.reconstruction.specs import design_dir

    rc = main(["tolerance", "--design", str(design_dir("hdr")), "--out", str(tmp_path / "typo"), "--resume"])
    assert rc == 2 and "holds no tolerance study to continue" in capsys.readouterr().err
    assert not (tmp_path / "typo").exists()


def test_a_force_finetune_stopped_before_its_first_step_says_the_earlier_checkpoint_is_untouched(tmp_path, capsys,
                                                                                                monkeypatch):
    """finetune clears an earlier run's checkpoint only where its loop starts (a refused run keeps it): a --force run
    interrupted in its set-up leaves that checkpoint as it was, and the hint says so (a --resume would continue the
    earlier run, not start this one); once the run saved its own, the hint is --resume in place of --force."""
    import doefab.reconstruction.endtoend as e2e
    from cli_helpers import REPO

    out = tmp_path / "ft"
    argv = ["finetune", "--design", str(REPO / "masks" / "half-ring"), "--minutes", "1", "--out", str(out)]

    def saved(tag):
        def stop(design, path, **kw):
            (path / "checkpoint.pt").write_bytes(tag)  # what the loop saves at a step
            raise KeyboardInterrupt
        return stop

    def set_up_only(design, path, **kw):
        raise KeyboardInterrupt  # still computing the design's PSFs

    monkeypatch.setattr(e2e, "finetune_end_to_end", saved(b"earlier"))
    assert main(argv) == 130
    assert "rerun the same command with --resume to continue" in capsys.readouterr().err
    monkeypatch.setattr(e2e, "finetune_end_to_end", set_up_only)
    assert main([*argv, "--force"]) == 130
    err = capsys.readouterr().err
    assert f"the earlier run's checkpoint in {out} is kept, untouched" in err and "--resume in place of --force to " \
        "continue the earlier run" in err, err
    assert (out / "checkpoint.pt").read_bytes() == b"earlier"
    monkeypatch.setattr(e2e, "finetune_end_to_end", saved(b"this run"))
    assert main([*argv, "--force"]) == 130
    err = capsys.readouterr().err
    assert "rerun the same command with --resume in place of --force to continue" in err and "untouched" not in err
