"""``doefab evaluate``: a design of another task is named as such, at once."""

from cli_helpers import run_cli


def test_evaluate_names_the_task_design_mismatch(tmp_path, capsys):
    rc, _, err = run_cli(["evaluate", "--task", "depth", "--design", "masks/grating", "--weights-dir", "doefab/weights",
                       "--images", "1", "--size", "64", "--out", tmp_path / "ev"], capsys)
    assert rc == 2 and "--task depth needs a half-ring design" in err and "doefab train" not in err
