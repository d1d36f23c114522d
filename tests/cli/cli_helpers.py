"""Helpers of the command-line tests: a copy of the HDR scene with lines replaced, a snapshot of a folder, and a
``doefab`` call that returns its exit status and output."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def scene_copy(tmp: Path, name: str = "X.toml", **lines) -> Path:
    """A copy of scenes/hdr.toml with whole lines replaced: ``stages='stages = ["holder"]'``."""
    text = (REPO / "scenes" / "hdr.toml").read_text()
    for key, line in lines.items():
        text, n = re.subn(rf"(?m)^{key} = .*$", line, text)
        assert n == 1, key
    (tmp / name).write_text(text)
    return tmp / name


def holder_scene(tmp: Path) -> Path:
    """``scene_copy`` running the holder stage alone, as S.toml."""
    return scene_copy(tmp, "S.toml", stages='stages = ["holder"]')


def snapshot(root: Path) -> dict:
    """Every path under ``root`` with its bytes (None for a folder)."""
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


def run_cli(argv, capsys) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``doefab ARGV`` (parse-time errors included)."""
    from doefab.cli import main

    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:
        rc = exc.code
    cap = capsys.readouterr()
    return rc, cap.out, cap.err
