"""The sources of error (``doefab.tolerance.sources``): one row each holds a source's budget keys, its draws, its
surrogate parameters and, for an effect after the pupil, its physics; a new source is one row."""

from dataclasses import replace

import numpy as np
import pytest
import torch

import doefab
from doefab.design.design import Design
from doefab.errors import DoefabError
from doefab.tolerance import montecarlo, sources, study
from doefab.tolerance.errors import DEFAULT_BUDGET, PartErrors, load_budget, sample_errors
from doefab.tolerance.kinds import KINDS
from doefab.tolerance.surrogate import features, parameters


def test_every_judged_kind_names_a_source_and_every_source_is_judged():
    """The report judges each source of error at least once (a source no kind names would be drawn but never
    ranked), a kind's source is a row of the table, and each kind says what would remove it ("would buy the
    most")."""
    names = {s.name for s in sources.SOURCES}
    assert {k.source for k in KINDS} == names
    assert all(k.remedy.strip() for k in KINDS), [k.name for k in KINDS if not k.remedy.strip()]  # the report's


def test_the_shipped_budget_sets_every_key_of_the_table_and_no_other():
    import tomllib

    shipped = tomllib.loads(DEFAULT_BUDGET.read_text())
    keys = sources.budget_keys()
    given = {(sec, k) for sec, v in shipped.items() if sec != "spec" for k in v}
    assert given == {(sec, k) for sec, v in keys.items() if v is not None for k in v}


def test_whole_number_keys_refuse_fractions(tmp_path):
    f = tmp_path / "b.toml"
    f.write_text("[sensor]\ncalibration_rows = 10.5\n")
    with pytest.raises(DoefabError, match="calibration_rows = 10.5 counts something"):
        load_budget(f)


def _staircase(root, wavelengths):
    """A 4-level staircase of 10-pixel steps on an 80-pixel grid, the PSF inside its window: judged in a second."""
    cam = doefab.Camera(aperture_diameter=0.4e-3, doe_pitch=5.4e-6, doe_pixels=80, sensor_pitch=5.4e-6,
                        sensor_distance=20e-3, focus_distance=5.0)
    lv = np.tile((np.arange(80) // 10 % 4).astype(np.uint8), (80, 1))
    lv[:, 40:] = 3
    d = Design(task="streak", task_params={"kernel_size": 31, "arm_px": 8}, camera=cam, wavelengths=wavelengths,
               depths=(5.0,), height=doefab.levels_to_height(lv, cam, 4), levels=lv, n_levels=4,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d.save(root / "design")
    return root / "design"


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory):
    return _staircase(tmp_path_factory.mktemp("toysource"), (550e-9,))


def _scatter(psf, loss):
    """``psf`` [..., K, K] with a fraction ``loss`` of its light spread evenly over its window."""
    total = psf.sum(dim=(-2, -1), keepdim=True)
    return psf * (1 - loss) + loss * total / (psf.shape[-1] * psf.shape[-2])


def _toy_source():
    """A toy source: a drawn fraction of the coded half's light scattered evenly over the PSF window (stray light
    from a coating), applied to the part's coded PSF."""
    def draw(b, rng, m):
        return {"extra": {"coded_loss": abs(float(rng.normal(0, sources.budget_value(b, "toy", "loss_sigma_percent")
                                                             / 100)))}}

    def psf(psfs, part):
        return {h: (_scatter(v, part.extra.get("coded_loss", 0.0)) if h == "coded" else v) for h, v in psfs.items()}

    def params(b, chain, n, gap):
        s = sources.budget_value(b, "toy", "loss_sigma_percent") / 100
        return [sources.Param("coded loss", 2 * s, lambda p, x: replace(p, extra={**p.extra, "coded_loss": x}),
                              lambda p: p.extra.get("coded_loss", 0.0))] if s > 0 else []
    return sources.Source("coded loss", (sources.BudgetKey("toy", "loss_sigma_percent", 0, 50),), draw=draw,
                          params=params, psf=psf)


def test_a_toy_source_of_error_is_one_row(design_dir, tmp_path, monkeypatch):
    """Appending one row gives its budget key a range check, its draw a place after the others (their draws
    unchanged), its effect on every judged part, and the surrogate its parameter."""
    mount = "[mounting]\ndecenter_max_mm = 0\naxial_gap_mm = 0\n"  # the small test part keeps its light in the window
    plain, f = tmp_path / "plain.toml", tmp_path / "budget.toml"
    plain.write_text(mount)
    f.write_text(mount + "[toy]\nloss_sigma_percent = 10\n")
    with pytest.raises(DoefabError, match=r"unknown section \[toy\]"):
        load_budget(f)
    without = sample_errors(load_budget(plain), np.random.default_rng(4), n_masks=2)
    monkeypatch.setattr(sources, "SOURCES", (*sources.SOURCES, _toy_source()))
    budget = load_budget(f)
    bad = tmp_path / "bad.toml"
    bad.write_text("[toy]\nloss_sigma_percent = 80\n")
    with pytest.raises(DoefabError, match="toy.loss_sigma_percent = 80 is outside 0–50"):
        load_budget(bad)

    part = sample_errors(budget, np.random.default_rng(4), n_masks=2)
    loss = part.extra["coded_loss"]
    assert 0 < loss < 0.5 and replace(part, extra={}) == replace(without, extra={})

    j = study.judge_for(str(design_dir), 1)
    with torch.no_grad():  # an independent route: the part without its loss, its light spread by hand
        plain = j.psfs(replace(part, extra={}))["coded"].double()
        k = plain.shape[-1]
        want = j.score(plain * (1 - loss) + loss * plain.sum(dim=(-2, -1), keepdim=True) / k**2, part)["metric"]
    got = j.evaluate(part)["metric"]
    assert got == pytest.approx(want, rel=1e-9) and got < j.evaluate(replace(part, extra={}))["metric"]

    rows = montecarlo.monte_carlo(design_dir, budget, 1, tmp_path / "mc", seed=2, progress=False)
    assert rows[0]["errors"]["extra"]["coded_loss"] > 0  # drawn in the study, and judged with it (the part's
    # errors as the study logged them, judged again here with the toy's effect and without it)
    logged = PartErrors(**rows[0]["errors"])
    assert rows[0]["metric"] == pytest.approx(j.evaluate(logged)["metric"], rel=1e-9)
    assert rows[0]["metric"] != pytest.approx(j.evaluate(replace(logged, extra={}))["metric"], rel=1e-6)

    params = parameters(budget, j.chain, 2)
    assert params[-1].name == "coded loss" and params[-1].h == pytest.approx(0.2)
    assert features(part, budget, j.chain, 2)[-1] == pytest.approx(loss)


def _traced_opd(theta: float, n: float, h: float = 1.0) -> float:
    """The optical path a glass step of height h adds to a ray meeting it at ``theta``, traced with Snell's law:
    the path inside the glass, n·h / cos θ_t, less the air path between the same wavefronts, (h / cos θ_t)·
    cos(θ − θ_t)."""
    import math

    t = math.asin(math.sin(theta) / n)
    inside = h / math.cos(t)
    return n * inside - inside * math.cos(theta - t)


@pytest.mark.parametrize("deg", [0.5, 5.0, 20.0, 40.0])
@pytest.mark.parametrize("n", [1.46, 1.7])
def test_the_tilt_factor_is_the_ray_traced_path_through_a_step(deg, n):
    import math

    got = sources.tilt_phase_factor(math.radians(deg), n)
    assert got == pytest.approx(_traced_opd(math.radians(deg), n) / (n - 1), rel=1e-12)
    if deg <= 5:  # second order in θ for small tilts
        assert got - 1 == pytest.approx(math.radians(deg) ** 2 / (2 * n), rel=0.01)


@pytest.fixture(scope="module")
def two_band_dir(tmp_path_factory):
    """The staircase designed for two wavelengths (blue and red: two substrate indices)."""
    return _staircase(tmp_path_factory.mktemp("tilt2"), (450e-9, 650e-9))


def test_a_tilted_part_is_its_relief_deepened_by_the_traced_path(design_dir, two_band_dir):
    """The judge's PSF of a die tilted 20° equals, at each wavelength, the PSF of the design's height map deepened
    by the ray-traced path ratio at that wavelength's index (an explicit height map, the judge's other route); the
    budget's 1σ tilt changes the PSF metric by less than a part in 10^4."""
    import math

    j = study.judge_for(str(two_band_dir), 1)
    theta = math.radians(20.0)
    full = (1 << j.n_masks) - 1
    lv = j.design.levels.astype(np.float64)
    with torch.no_grad():
        got = j.psfs(PartErrors(mount_tilt=theta))["coded"].double()
        flat = j.psfs(PartErrors())["coded"].double()
        for i, wl in enumerate(j.design.wavelengths):
            n = float(j.design.camera.material.index(wl))
            ratio = _traced_opd(theta, n) / (n - 1)
            want = j.psf_from_height(full * j.step - ratio * (full - lv) * j.step)[:, i]
            assert float((got[:, i] - want).abs().max()) < 1e-5 * float(want.max()), wl
    assert float((got - flat).abs().max()) > 1e-3 * float(flat.max())  # 20° is seen
    one = study.judge_for(str(design_dir), 1)
    sigma = KINDS_BY_NAME["mount tilt"].from_budget(load_budget())
    assert math.degrees(sigma) == pytest.approx(0.25)
    m0, m1 = one.evaluate(PartErrors())["metric"], one.evaluate(PartErrors(mount_tilt=sigma))["metric"]
    assert abs(m1 - m0) < 1e-4 * abs(m0)


KINDS_BY_NAME = {k.name: k for k in KINDS}
