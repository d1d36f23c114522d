"""Fixtures of the tolerance tests."""

import numpy as np
import pytest

import doefab
from doefab.design.design import Design


@pytest.fixture(scope="session")
def depth_design(tmp_path_factory):
    """A 100-pixel half-ring part of random levels on 3 planes (1, 2, 5 m): a depth design that judges fast."""
    cam = doefab.Camera(aperture_diameter=0.54e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=20e-3, focus_distance=3.5)
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    lv[:, 50:] = 15
    d = Design(task="half-ring", task_params={"kernel_size": 63, "ring_law": "defocus"}, camera=cam,
               wavelengths=(656e-9, 589e-9, 486e-9), depths=(1.0, 2.0, 5.0), height=doefab.levels_to_height(lv, cam),
               levels=lv, metrics={"name": "m", "continuous": 0.1, "quantized": 0.1})
    root = tmp_path_factory.mktemp("cond")
    d.save(root / "design")
    return root / "design"


@pytest.fixture(scope="session")
def design_dir(tmp_path_factory):
    """A 100-pixel streak design of one band whose coded half is a 16-level staircase: a design that judges fast."""
    root = tmp_path_factory.mktemp("tol")
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    row = (np.arange(100) % 16).astype(np.uint8)
    lv = np.tile(row, (100, 1))
    lv[:, 50:] = 15  # plain half
    d = Design(task="streak", task_params={"kernel_size": 31, "arm_px": 8}, camera=cam, wavelengths=(550e-9,),
               depths=(5.0,), height=doefab.levels_to_height(lv, cam), levels=lv,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d.save(root / "design")
    return root / "design"


@pytest.fixture
def fake_judges(monkeypatch):
    """Stand-ins for a design's PSF judge (every part at metric 0.5) and its network judge (a network of 63-px
    kernels that renders elsewhere, as depth does), so a tornado's bookkeeping runs without any PSF."""
    from contextlib import nullcontext
    from types import SimpleNamespace

    import torch

    from doefab.tolerance import study

    nj = SimpleNamespace(rec=SimpleNamespace(pair=SimpleNamespace(coded=torch.zeros(3, 3, 63, 63))),
                         renders_elsewhere=True)
    monkeypatch.setattr(study, "network_judge_for", lambda *a, **k: nj)
    judge = SimpleNamespace(n_masks=4, nominal=None, score=lambda part: {"metric": 0.5},
                            computing_at=lambda kernel: nullcontext())
    monkeypatch.setattr(study, "judge_for", lambda d, s=1: judge)
    return judge
