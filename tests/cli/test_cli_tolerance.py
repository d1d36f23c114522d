"""``doefab tolerance``: the Dask scheduler is checked when the flags are parsed, and reached before any work."""

import subprocess
import sys

import pytest

from cli_helpers import REPO, run_cli


@pytest.mark.parametrize("scheduler", ["local:0", "local:abc", "tcp://nohost"])
def test_scheduler_checked_at_parse_time(tmp_path, scheduler):
    """Run as its own process with a time limit: the case used to hang until killed."""
    p = subprocess.run([sys.executable, "-m", "doefab", "tolerance", "--design", str(REPO / "masks" / "grating"),
                        "--samples", "1", "--scheduler", scheduler, "--out", str(tmp_path / "t0")],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 2 and "--scheduler" in p.stderr and not (tmp_path / "t0").exists()


def test_an_unreachable_scheduler_is_refused_before_any_work(tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rc, _, err = run_cli(["tolerance", "--design", REPO / "masks" / "grating", "--samples", "1", "--scheduler",
                       f"tcp://127.0.0.1:{port}", "--out", tmp_path / "t0"], capsys)
    assert rc == 2 and "no Dask scheduler answers" in err and not (tmp_path / "t0").exists()


def test_a_budget_whose_calibration_its_noise_swamps_is_warned_of_at_the_cli(tmp_path, capsys):
    """One dim calibration row (36 % scatter of a 5 % ratio) is warned of on stderr before the study's own checks
    (here --resume with --force, refused before any work); the shipped budget is not."""
    (tmp_path / "dim.toml").write_text("[sensor]\ncalibration_rows = 1\ncalibration_level = 0.01\n")
    for budget, warned in ((tmp_path / "dim.toml", True), ("default", False)):
        rc, _, err = run_cli(["tolerance", "--design", REPO / "masks" / "grating", "--samples", "1", "--budget",
                              budget, "--resume", "--force", "--out", tmp_path / "t0"], capsys)
        assert rc == 2 and "give one of them" in err and not (tmp_path / "t0").exists()
        assert ("warning: tolerance budget [sensor]: a crosstalk calibration of 1 row" in err) is warned, err
