import subprocess
import sys

import numpy as np
import pytest

from doefab.cli import main


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for cmd in ("demo", "psf", "design", "masks", "holder"):
        assert cmd in out


@pytest.mark.parametrize("cmd", ["demo", "psf", "design", "masks", "holder"])
def test_subcommand_help(cmd, capsys):
    with pytest.raises(SystemExit) as exc:
        main([cmd, "--help"])
    assert exc.value.code == 0
    assert "--out" in capsys.readouterr().out


def test_psf_command_writes_outputs(tmp_path):
    rc = main(["psf", "--wavelengths-nm", "550", "--depths-m", "inf", "5", "--kernel", "63",
               "--out", str(tmp_path)])
    assert rc == 0
    data = np.load(tmp_path / "psf.npz")
    assert data["coded"].shape == (2, 1, 63, 63)
    assert (tmp_path / "psf.png").stat().st_size > 1000


def test_psf_command_bad_input_is_one_clear_error(tmp_path, capsys):
    np.save(tmp_path / "h.npy", np.zeros((10, 10)))
    assert main(["psf", "--height", str(tmp_path / "h.npy"), "--out", str(tmp_path / "o")]) == 2
    assert "has shape (10, 10)" in capsys.readouterr().err
    assert main(["psf", "--height", str(tmp_path / "missing.npy"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err


def test_entry_point_runs():
    out = subprocess.run([sys.executable, "-m", "doefab", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "SUBCOMMAND" in out.stdout


def test_top_level_help_is_a_paragraph_and_one_line_per_subcommand(capsys, monkeypatch):
    """``doefab --help`` (80 columns): what doefab does in plain words, no developer's docstring, and each
    subcommand with its one-line purpose on one line."""
    from doefab.cli import build_parser

    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    assert "``" not in text and "pass through" not in text
    assert "split-aperture diffractive optical element" in text
    names = list(build_parser()._subparsers._group_actions[0].choices)
    lines = text.splitlines()
    for name in names:
        row = [ln for ln in lines if ln.startswith("    ") and ln.split()[:1] == [name]]
        assert len(row) == 1 and len(row[0].split()) > 3, name  # the name and its purpose on the same line
        i = lines.index(row[0])
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        assert not nxt.startswith(" " * 10) or nxt.split()[:1] in ([n] for n in names), (name, nxt)
    assert max(len(ln) for ln in lines) <= 80
