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
