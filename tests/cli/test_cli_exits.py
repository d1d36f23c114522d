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
