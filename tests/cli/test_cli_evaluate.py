"""``doefab evaluate``: a design of another task is named as such, at once."""

from cli_helpers import run_cli


def test_evaluate_names_the_task_design_mismatch(tmp_path, capsys):
    rc, _, err = run_cli(["evaluate", "--task", "depth", "--design", "masks/grating", "--weights-dir", "doefab/weights",
                       "--images", "1", "--size", "64", "--out", tmp_path / "ev"], capsys)
    assert rc == 2 and "--task depth needs a half-ring design" in err and "doefab train" not in err


def test_an_interrupted_read_of_the_final_split_keeps_its_ledger(tmp_path, capsys, monkeypatch):
    """The ledger line is written before the first scene is scored; an interrupt after it keeps the new folder
    with its ledger (a read is a read) and says so, where any other failed evaluation leaves nothing."""
    import doefab.reconstruction.evaluate as ev

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ev, "_score", interrupted)
    argv = ["evaluate", "--task", "hdr", "--variants", "uncoded_only", "--images", "1", "--size", "64", "--clean"]
    rc, _, err = run_cli(argv + ["--split", "final", "--out", tmp_path / "f"], capsys)
    ledger = tmp_path / "f" / ev.FINAL_LEDGER
    assert rc == 130 and ledger.is_file() and "| hdr | 1 scenes of 64² px" in ledger.read_text()
    assert "logged in" in err and "which is kept" in err
    rc, _, err = run_cli(argv + ["--split", "val", "--out", tmp_path / "v"], capsys)
    assert rc == 130 and not (tmp_path / "v").exists() and "nothing was kept" in err
