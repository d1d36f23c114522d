"""The fitted errors' uncertainty (``lab.uncertainty``): the precision an error must be told to."""

import math
from pathlib import Path

import numpy as np

from doefab.lab.partmodel import Param
from doefab.lab.uncertainty import curvature
from doefab.tolerance.errors import load_budget


def _orthogonal(sigmas, n=300, seed=0):
    """(r, jac) whose least-squares σ are ``sigmas`` (budget σ) with s² = 1."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(n, len(sigmas) + 1)))
    r = q[:, -1] * math.sqrt(n - len(sigmas))
    return r, q[:, :-1] / np.asarray(sigmas)


def test_an_etch_depth_is_identified_only_to_its_precision():
    """An etch depth scale (budget σ 3 %) with σ 0.4 budget σ (1.2 %) is not identified, as its 2σ interval is
    wider than ±2 %, though below half the budget's σ; one with σ 0.3 (0.9 %) is, and so is an edge bias (no
    precision of its own) at 0.45 budget σ. The shipped model gives the etch depths that precision."""
    etch = Param("etch_depth_scale", 0, None, "", 1.0, 0.03, 1.0, precision=0.01)
    bias = Param("edge_bias", None, None, "µm", 1e-6, 1e-7, 0.0)
    r, jac = _orthogonal([0.4, 0.3, 0.45])
    got = curvature([etch, etch, bias], r, jac)
    np.testing.assert_allclose(got["sigma"], [0.4, 0.3, 0.45], rtol=1e-9)
    assert got["identifiable"] == [False, True, True]
    assert "(1.2 %) is above the 1 %" in got["reason"][0]
    r, jac = _orthogonal([0.33, 0.34])  # σ 0.99 % is told to the precision; 1.02 % is not
    assert curvature([etch, etch], r, jac)["identifiable"] == [True, False]
    from doefab.lab import diagnose, uncertainty

    assert diagnose.curvature is uncertainty.curvature and diagnose.estimate is uncertainty.estimate
    from doefab.design.design import Design
    from doefab.lab.partmodel import ETCH_PRECISION, parameters

    cam = Design.load(Path(__file__).resolve().parents[2] / "masks" / "streak" / "design").camera
    made = parameters(load_budget(), 4, cam, (cam.focus_distance,))
    assert ETCH_PRECISION == 0.01 and all((p.precision == ETCH_PRECISION) == (p.key == "etch_depth_scale")
                                          for p in made)
