"""``doefab doctor``'s "the system" table for a camera that is not the prototype, against hand-computed optics
(thin lens, Airy radius, first-order grating spots, N-BK7's index from SCHOTT's Sellmeier coefficients)."""

import math
from pathlib import Path

import pytest

from doefab.pipeline.doctor import explain
from doefab.pipeline.scene import load_scene
from doefab.pipeline.system import resolve

REPO = Path(__file__).resolve().parents[2]


def _nbk7(lam_um: float) -> float:  # SCHOTT N-BK7 data sheet: B1..B3, C1..C3 (µm²)
    b = (1.03961212, 0.231792344, 1.01046945)
    c = (0.00600069867, 0.0200179144, 103.560653)
    x = lam_um ** 2
    return math.sqrt(1 + sum(bi * x / (x - ci) for bi, ci in zip(b, c)))


def test_my_camera_scene_is_explained_by_hand_computed_optics():
    res = resolve(load_scene(REPO / "scenes" / "my_camera.toml"))
    rows = {r["quantity"]: r["value"] for r in explain(res)}
    f, z, n_f = 35e-3, 5.0, 4.0
    s = 1 / (1 / f - 1 / z)  # thin lens focused at 5 m
    d = f / n_f
    assert rows["f-number (DOE aperture)"] == pytest.approx(4.0, rel=1e-9)
    assert rows["DOE pixels across the aperture"] == 2188  # 8.75 mm / 4 µm, even
    assert rows["diffraction limit (Airy radius)"] == pytest.approx(1.22 * 550e-9 * s / d / 3.76e-6, rel=1e-6)
    spread = (650e-9 - 450e-9) * s / 96e-6 / 3.76e-6  # first orders s·λ/Λ at the band's ends
    assert rows["grating dispersion across the band"] == pytest.approx(spread, rel=1e-3)
    n = _nbk7(0.55)
    assert rows["substrate index"] == pytest.approx(n, abs=2e-5)
    assert rows["etch depth of 2π"] == pytest.approx(550 / (n - 1), rel=1e-4)
    assert res["settings"]["levels"] == 8 and len(res["settings"]["wavelengths_m"]) == 21
