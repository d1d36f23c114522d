"""Honest capture conditions: each split's own fabricated parts, depth between the network's planes, crosstalk
calibrated from noisy white walls — the captures a network did not make (issue 23)."""

import numpy as np
import pytest
import torch

import doefab
from doefab.design.design import Design
from doefab.tolerance import conditions as C
from doefab.reconstruction.specs import make_batch


@pytest.fixture(scope="module")
def depth_design(tmp_path_factory):
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


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    root = tmp_path_factory.mktemp("cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DOEFAB_CACHE", str(root))
        yield root


@pytest.fixture(scope="module")
def honest(depth_design, cache):
    return {s: C.honest("depth", depth_design, s, parts=2) for s in ("train", "val", "test")}


def test_every_split_has_its_own_fabricated_parts(honest):
    psfs = {s: torch.stack([p.coded for p in c.parts]) for s, c in honest.items()}
    for a, b in (("train", "val"), ("train", "test"), ("val", "test")):
        assert float((psfs[a] - psfs[b]).abs().max()) > 1e-4
    assert float((psfs["test"][0] - psfs["test"][1]).abs().max()) > 1e-4  # two parts, not one twice


def test_depth_is_rendered_between_the_networks_planes(honest, depth_design):
    planes = honest["test"].parts[0].depths
    net = Design.load(depth_design).depths
    assert len(planes) == (len(net) - 1) * C.DEPTH_REFINE + 1
    inv = np.array([1 / z for z in planes])
    assert np.allclose(np.diff(inv), np.diff(inv)[0])  # uniform in inverse depth
    assert sum(any(abs(z - w) < 1e-9 for w in net) for z in planes) == len(net)  # the rest lie between them


def test_honest_captures_differ_from_clean_ones_of_the_same_scene(honest, depth_design):
    from doefab.reconstruction.specs import psf_pair

    pair, _ = psf_pair("depth", depth_design)
    clean = make_batch("depth", "test", [1], 64, pair)
    real = make_batch("depth", "test", [1], 64, pair, conditions=honest["test"])
    assert torch.equal(clean[2], real[2])  # the same scene and depth map
    assert float((clean[0] - real[0]).abs().mean()) > 1e-3
    xt = honest["test"].crosstalk_for(1, 4, 64)
    assert xt is not None and xt.estimate is not None  # the default budget's camera is calibrated
    assert not np.allclose(xt.estimate[0], xt.alpha_lr)  # with a calibration error of its own


def test_parts_come_back_from_the_cache(honest, depth_design, cache):
    again = C.honest("depth", depth_design, "val", parts=2)
    assert all(torch.equal(a.coded, b.coded) for a, b in zip(again.parts, honest["val"].parts))
    assert len(list((cache / "conditions").glob("depth-*.pt"))) == 3


def test_make_batch_records_the_views_through_the_crosstalk_of_each_scenes_place(depth_design):
    """Eq. 29's mix reaches the captures (uncalibrated: the views stay mixed), and scenes spread across the
    sensor see different ratios (the per-column profile), not all the centre's."""
    from dataclasses import replace

    from doefab.reconstruction.specs import psf_pair
    from doefab.tolerance.errors import load_budget, sensor_errors
    from doefab.tolerance.surrogate import base_part

    budget = load_budget()
    sensor = replace(base_part(budget), **sensor_errors(budget))
    raw = C.Conditions(name="x", crosstalk=replace(sensor, calibrated=False), split="test")
    pair, _ = psf_pair("depth", depth_design)
    clean = make_batch("depth", "test", [1], 64, pair, noise="none")
    mixed = make_batch("depth", "test", [1], 64, pair, noise="none", conditions=raw)
    # the coded view gains α_r→l of the plain one and loses α_l→r of its own (Eq. 29), column by column
    assert float((mixed[0] - clean[0]).abs().max()) > 1e-3
    ends = [raw.crosstalk_for(i, 12, 64) for i in (0, 11)]
    assert abs(float(np.mean(ends[0].alpha_lr)) - float(np.mean(ends[1].alpha_lr))) > 1e-3
    # the place a scene is rendered at follows ``images``: the same scene at the sensor's edge records otherwise
    centre = make_batch("depth", "test", [0], 64, pair, noise="none", conditions=raw, images=1)
    edge = make_batch("depth", "test", [0], 64, pair, noise="none", conditions=raw, images=12)
    assert float((centre[0] - edge[0]).abs().max()) > 1e-4


def test_evaluate_spreads_its_scenes_across_the_sensor(monkeypatch, tmp_path):
    """``evaluate`` renders scene i of N at its own place (``images=N``), so the test tables see the crosstalk
    profile across the sensor and not only the centre column's."""
    import doefab.reconstruction.evaluate as ev

    seen = []
    real = ev.make_batch

    def spy(*a, **kw):
        seen.append(kw.get("images"))
        return real(*a, **kw)

    monkeypatch.setattr(ev, "make_batch", spy)
    ev.evaluate("hdr", tmp_path, images=3, size=64, progress=False, variants=("uncoded_only",))
    assert seen == [3, 3, 3]


def test_parts_cached_by_other_model_code_are_not_reused(honest, depth_design, cache, monkeypatch):
    """The validation parts are cached (the ``honest`` fixture made them); under another model code the same
    request misses that file and computes its parts afresh."""
    from doefab.tolerance import judge

    before = set((cache / "conditions").glob("depth-*.pt"))
    assert before and C.model_sources_sha256() == C.model_sources_sha256() and len(C.model_sources_sha256()) == 64
    assert C.model_sources_sha256(("optics",)) != C.model_sources_sha256()  # every part-model package counts
    computed = []
    real_psfs = judge.PSFJudge.psfs
    monkeypatch.setattr(judge.PSFJudge, "psfs", lambda self, *a, **k: computed.append(1) or real_psfs(self, *a, **k))
    C.honest("depth", depth_design, "val", parts=2)
    assert computed == []  # the same code: served from the cache
    monkeypatch.setattr(C, "model_sources_sha256", lambda: "another version of the optics")
    C.honest("depth", depth_design, "val", parts=2)
    assert len(computed) == 2  # both parts computed again
    assert len(set((cache / "conditions").glob("depth-*.pt")) - before) == 1  # and kept apart


def test_the_crosstalk_calibration_scatters_with_the_sensors_shot_noise():
    """The white-wall calibration's estimate of a per-column ratio is shot-noise limited: its scatter across
    columns grows as 1/√(full well) — √125 ≈ 11.2× from 25 000 e⁻ to 200 e⁻ (no read noise) — so a scene's own
    sensor reaches the calibration, not the default's."""
    from doefab.imaging.sensor import Sensor
    from doefab.tolerance.errors import PartErrors, crosstalk_ratios

    err = PartErrors(crosstalk=(0.03, 0.03), calibration_rows=256)
    cols = np.arange(512) - 255.5
    scatter = []
    for full_well in (25_000.0, 200.0):
        a, _, a_hat, _ = crosstalk_ratios(err, cols, Sensor(full_well_e=full_well, read_noise_e=0.0).noise())
        scatter.append(np.std(a_hat - a))
    assert scatter[1] / scatter[0] == pytest.approx(np.sqrt(25_000 / 200), rel=0.15)


def test_make_batch_calibrates_the_crosstalk_with_the_captures_own_noise(depth_design, monkeypatch):
    """The calibration behind a calibrated camera's unmix draws the same sensor noise as the captures."""
    from dataclasses import replace

    import doefab.tolerance.errors as errors
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.specs import psf_pair
    from doefab.tolerance.errors import load_budget, sensor_errors
    from doefab.tolerance.surrogate import base_part

    real, seen = errors.crosstalk_ratios, []

    def spy(err, columns, noise="default"):
        seen.append(noise)
        return real(err, columns, noise)

    monkeypatch.setattr(errors, "crosstalk_ratios", spy)
    budget = load_budget()
    cond = C.Conditions(name="x", crosstalk=replace(base_part(budget), **sensor_errors(budget)), split="test")
    assert cond.crosstalk.calibrated
    pair, _ = psf_pair("depth", depth_design)
    make_batch("depth", "test", [1], 64, pair, noise=Sensor(full_well_e=900.0, read_noise_e=7.0).noise(),
               conditions=cond)
    assert len(seen) == 1 and (seen[0].full_well_e, seen[0].read_noise_e) == (900.0, 7.0)
