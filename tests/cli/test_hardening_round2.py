"""One test per row of the second hardening issue (issue 21), each replaying the row's exact case."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import doefab
from doefab.cli import main
from doefab.errors import DoefabError

REPO = Path(__file__).resolve().parents[2]


def _scene(tmp: Path, name: str = "X.toml", **lines) -> Path:
    """A copy of scenes/hdr.toml with whole lines replaced: ``stages='stages = ["holder"]'``."""
    text = (REPO / "scenes" / "hdr.toml").read_text()
    for key, line in lines.items():
        text, n = re.subn(rf"(?m)^{key} = .*$", line, text)
        assert n == 1, key
    (tmp / name).write_text(text)
    return tmp / name


def _holder_scene(tmp: Path) -> Path:
    return _scene(tmp, "S.toml", stages='stages = ["holder"]')


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


def _run(argv, capsys) -> tuple[int, str, str]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # parse-time errors
        rc = exc.code
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


# ---- rows 7 and 8: units and ranges at the API

def test_row07_fabricated_height_gives_the_unit_error(tiny_camera):
    levels = np.zeros((tiny_camera.doe_pixels,) * 2, np.uint8)
    with pytest.raises(DoefabError, match="550 nm is 5.5e-07 m"):
        doefab.fabricated_height(levels, tiny_camera, design_wavelength=550)
    with pytest.raises(DoefabError, match="550 nm is 5.5e-07 m"):
        doefab.Camera(design_wavelength=550)


def test_row08_reconstructor_refuses_captures_outside_0_1():
    rec = doefab.load_reconstructor("hdr")
    rng = np.random.default_rng(0)
    coded, uncoded = rng.random((3, 64, 64)).astype(np.float32), rng.random((3, 64, 64)).astype(np.float32)
    with pytest.raises(DoefabError, match=r"captures are in \[0, 1\].*divide by the white level"):
        rec(coded * 255, uncoded * 255)
    with pytest.raises(DoefabError, match="integer .uint8. image.*255 for 8 bits"):
        rec((coded * 255).astype(np.uint8), (uncoded * 255).astype(np.uint8))
    with pytest.raises(DoefabError, match="subtract the black level"):
        rec(coded - 0.5, uncoded)

