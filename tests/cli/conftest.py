"""Shared by the command-line error tests: a small design and its mask set, and the check that a wrong input
gets one clear line, the right exit status and leaves every file as it was."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(scope="session")
def fixtures(tmp_path_factory):
    """A small design folder and its mask set (100 × 100 pixels at 5.4 µm), made once."""
    import doefab
    from doefab.design.design import Design
    from doefab.fabrication.export import MaskOptions, export_masks

    root = tmp_path_factory.mktemp("fixtures")
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    d = Design(task="grating", task_params={}, camera=cam, wavelengths=(550e-9, 600e-9), depths=(5.0,),
               height=doefab.levels_to_height(lv, cam), levels=lv,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5, "continuous_worst": 0.4,
                        "quantized_worst": 0.4})
    d.save(root / "design")
    export_masks(d, root / "maskset", MaskOptions(use_klayout=False), design_dir=root / "design", progress=False)
    return root


def tree(root: Path) -> dict:
    """Every file and folder under ``root`` with its size and modification time."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            out[str(p.relative_to(root))] = (p.is_dir(), st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture
def one_clear_error(fixtures, tmp_path, capsys, monkeypatch):
    """``check(build, status, needle)``: run ``doefab`` with ``build(fixtures, work_dir)`` as its arguments in an
    empty working folder; assert the exit status, exactly one line on stderr holding ``needle``, no traceback,
    and nothing created, changed or removed under the test's folder or the fixtures."""
    from doefab.cli import main

    def check(build, status: int, needle: str) -> str:
        work = tmp_path / "work"
        work.mkdir()
        monkeypatch.chdir(work)
        argv = [str(a) for a in build(fixtures, work)]
        before, fixtures_before = tree(tmp_path), tree(fixtures)
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse usage errors
            rc = exc.code
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert rc == status, f"{argv}: exit {rc}, stderr: {err}"
        assert len(lines) == 1, f"{argv}: expected one line, got {lines}"
        assert "Traceback" not in err
        assert needle in lines[0], f"{argv}: {needle!r} not in {lines[0]!r}"
        assert "pupil_oversample" not in lines[0] and "Camera." not in lines[0] and "die_m" not in lines[0]
        assert tree(tmp_path) == before, f"{argv}: files were created, changed or removed"
        assert tree(fixtures) == fixtures_before
        return lines[0]

    return check
