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
    net = sorted(Design.load(depth_design).depths)
    assert len(planes) == (len(net) - 1) * C.DEPTH_REFINE + 1
    assert all(any(z == w for z in planes) for w in net)  # the network's planes are among them
    inv = 1 / np.array(planes)
    for near, far in zip(net, net[1:]):  # the rest lie between them, evenly in inverse depth within each interval
        inside = inv[(inv <= 1 / near) & (inv >= 1 / far)]
        assert len(inside) == C.DEPTH_REFINE + 1
        assert np.allclose(np.diff(inside), (1 / far - 1 / near) / C.DEPTH_REFINE, rtol=1e-12)


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
    assert before
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

    def spy(err, columns, noise=None, rows=None):
        seen.append(noise)
        return real(err, columns, noise, rows=rows)

    monkeypatch.setattr(errors, "crosstalk_ratios", spy)
    budget = load_budget()
    cond = C.Conditions(name="x", crosstalk=replace(base_part(budget), **sensor_errors(budget)), split="test")
    assert cond.crosstalk.calibrated
    pair, _ = psf_pair("depth", depth_design)
    make_batch("depth", "test", [1], 64, pair, noise=Sensor(full_well_e=900.0, read_noise_e=7.0).noise(),
               conditions=cond)
    assert len(seen) == 1 and (seen[0].full_well_e, seen[0].read_noise_e) == (900.0, 7.0)


def _design(levels=None, n_levels=16, depths=(1.0, 2.0, 5.0), wavelengths=(656e-9, 589e-9, 486e-9), focus=3.5):
    """The fixture's depth design, built afresh (new arrays, a new camera) on every call."""
    cam = doefab.Camera(aperture_diameter=0.54e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=20e-3, focus_distance=focus)
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8) if levels is None else levels
    lv[:, 50:] = 15
    return Design(task="half-ring", task_params={"kernel_size": 63, "ring_law": "defocus"}, camera=cam,
                  wavelengths=wavelengths, depths=depths, height=doefab.levels_to_height(lv, cam, n_levels),
                  levels=lv, metrics={"name": "m", "continuous": 0.1, "quantized": 0.1}, n_levels=n_levels)


def test_the_parts_cache_key_changes_with_every_input_and_with_nothing_else(tmp_path, monkeypatch):
    """A cached part is reused only for the request that made it: changing any one input — the design's levels,
    its level count, planes, wavelengths or camera, a budget value, the split, the part count, the kernel, the
    alignment chain, the part-model code — gives another key; the same inputs built afresh (and a budget file
    that spells out none of the defaults it takes) give the same key."""
    from doefab.tolerance.errors import load_budget

    chain = {1: 0, 2: 0, 3: 0, 4: 0}
    key = lambda design=None, split="val", n=2, budget=None, kernel=95, ch=chain: C._key(  # noqa: E731
        "depth", design or _design(), split, n, budget or load_budget(), kernel, ch)
    base = key()
    empty = tmp_path / "empty.toml"
    empty.write_text("")
    defaults_listed = load_budget(empty)
    assert defaults_listed["defaults_used"]  # the same values, but every key listed as taken from the defaults
    assert key(budget=defaults_listed) == base == key(design=_design(levels=_design().levels.copy()), ch=dict(chain))
    wider = tmp_path / "wider.toml"
    wider.write_text("[overlay]\nshift_sigma_um = 1.5\n")
    other_levels = _design().levels
    other_levels[3, 7] = (int(other_levels[3, 7]) + 1) % 16
    changed = {"levels": key(design=_design(levels=other_levels)), "n_levels": key(design=_design(n_levels=32)),
               "depths": key(design=_design(depths=(1.0, 2.0, 4.0))),
               "wavelengths": key(design=_design(wavelengths=(656e-9, 589e-9, 480e-9))),
               "camera": key(design=_design(focus=3.0)), "budget": key(budget=load_budget(wider)),
               "split": key(split="test"), "count": key(n=3), "kernel": key(kernel=97),
               "chain": key(ch={1: 0, 2: 1, 3: 2, 4: 3})}
    monkeypatch.setattr(C, "model_sources_sha256", lambda: "0" * 64)
    changed["model code"] = key()
    assert {k for k, v in changed.items() if v == base} == set()
    assert len(set(changed.values())) == len(changed)  # and no two changes collide


def test_the_model_code_digest_reads_every_part_model_source(tmp_path, monkeypatch):
    """The digest of the part-model code changes with one byte of any file of ``optics``, ``fabrication`` or
    ``tolerance`` and with a file's name, not with code outside them nor with where the tree lies."""
    def tree(root, files):
        for rel, text in files.items():
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            (root / rel).write_text(text)
        return str(root / "tolerance" / "conditions.py")

    files = {"optics/psf.py": "a = 1\n", "optics/propagators/fft.py": "b = 2\n", "fabrication/levels.py": "c = 3\n",
             "tolerance/conditions.py": "d = 4\n", "tasks/hdr.py": "e = 5\n"}

    def digest(files, where="a"):
        monkeypatch.setattr(C, "__file__", tree(tmp_path / where / "doefab", files))
        return C.model_sources_sha256()

    base = digest(files)
    assert len(base) == 64 and digest(files, "elsewhere") == base
    assert digest({**files, "tasks/hdr.py": "e = 6\n"}, "b") == base  # not a part-model package
    for i, rel in enumerate(f for f in files if not f.startswith("tasks")):
        assert digest({**files, rel: files[rel].replace("=", "= 1 +")}, f"edit{i}") != base, rel
    moved = {("optics/propagators/mft.py" if k == "optics/propagators/fft.py" else k): v for k, v in files.items()}
    assert digest(moved, "moved") != base
    monkeypatch.undo()
    assert C.model_sources_sha256(("optics",)) != C.model_sources_sha256()  # every package of the real tree counts


def _budget_sensor(**changes):
    """The default budget's sensor (crosstalk, its slope and calibration) as a PartErrors."""
    from dataclasses import replace

    from doefab.tolerance.errors import load_budget, sensor_errors
    from doefab.tolerance.surrogate import base_part

    budget = load_budget()
    return replace(base_part(budget), **{**sensor_errors(budget), **changes})


def test_honest_captures_are_mixed_by_the_sensors_true_crosstalk_not_a_per_column_one(depth_design):
    """A scene's views are mixed by the true crosstalk of its sensor over its crop (rows and columns, the crops
    along the calibrated region's diagonal): ratios that change from row to row, which the captures carry as
    Eq. 29 with that map predicts."""
    from doefab.imaging.sensorcrosstalk import SensorCrosstalk
    from doefab.reconstruction.specs import psf_pair

    sensor = _budget_sensor(calibrated=False)
    raw = C.Conditions(name="x", crosstalk=sensor, split="test")
    xt = raw.crosstalk_for(1, 4, 64)
    assert np.shape(xt.alpha_lr) == (64, 64) == np.shape(xt.alpha_rl)
    assert float(np.ptp(xt.alpha_lr, axis=0).min()) > 1e-4  # every column's ratio changes along its rows
    seed = int(np.random.SeedSequence([C.PART_SEEDS["test"], 1]).generate_state(1)[0])
    offset = np.arange(64) - 31.5
    rows, cols = (2 / 3 - 0.5) * 0.8 * 3072 + offset, (1 / 3 - 0.5) * 0.8 * 3072 + offset
    a, b = SensorCrosstalk(sensor.crosstalk, sensor.crosstalk_slope, seed=seed).ratios(rows, cols, session=0)
    np.testing.assert_array_equal(xt.alpha_lr, a)
    np.testing.assert_array_equal(xt.alpha_rl, b)
    pair, _ = psf_pair("depth", depth_design)
    clean = make_batch("depth", "test", [1], 64, pair, noise="none")
    mixed = make_batch("depth", "test", [1], 64, pair, noise="none", conditions=raw, images=4)
    coded, plain = clean[0][0].double().numpy(), clean[1][0].double().numpy()
    want = np.clip(a * plain + (1 - b) * coded, 0, 1)  # Eq. 29: R* = α_l→r L + (1 − α_r→l) R, R the coded view
    np.testing.assert_allclose(mixed[0][0].double().numpy(), want, atol=2e-6)


def test_honest_conditions_state_the_residual_their_calibration_leaves():
    """``describe()`` states the RMS of true − calibrated ratio that the per-column calibration leaves (the
    sensor's ``SensorCrosstalk.residual``): a few per cent of the 5 % ratios; none without a calibration."""
    from doefab.tolerance.errors import sensor_crosstalk

    sensor = _budget_sensor()
    got = C.Conditions(name="honest", crosstalk=sensor, split="test").describe()["crosstalk_residual_rms"]
    want = sensor_crosstalk(sensor).residual(sensor.calibration_rows)
    np.testing.assert_allclose(got, want, rtol=5e-3)
    assert 1e-3 < min(got) and max(got) < 0.01
    assert C.Conditions(name="x", crosstalk=_budget_sensor(calibrated=False)).describe()[
        "crosstalk_residual_rms"] is None


def test_the_psf_level_judge_calibrates_with_the_parts_own_sensor(monkeypatch):
    """The PSF-level judge's unmix uses a calibration drawn with the part's sensor noise (the scene's, carried by
    ``PartErrors``), not the default sensor's: a 200 e⁻ full well scatters the estimate √125 ≈ 11× more than
    25 000 e⁻ (shot noise, no read noise)."""
    from types import SimpleNamespace

    import doefab.imaging.sensorcrosstalk as X
    from doefab.tolerance.errors import PartErrors, crosstalk_ratios, sensor_crosstalk
    from doefab.tolerance.judge import PSFJudge

    real, seen = X.simulate_calibration, []
    monkeypatch.setattr(X, "simulate_calibration", lambda *a, **k: seen.append(a[3]) or real(*a, **k))
    err = PartErrors(crosstalk=(0.05, 0.05), full_well_e=900.0, read_noise_e=7.0, calibration_rows=64)
    coded, plain = torch.rand(3, 1, 9, 9, dtype=torch.float64), torch.rand(3, 1, 9, 9, dtype=torch.float64)
    PSFJudge.coded_view(SimpleNamespace(uncoded=lambda: plain), coded, err)
    assert len(seen) == 1 and (seen[0].full_well_e, seen[0].read_noise_e) == (900.0, 7.0)
    cols, scatter = np.arange(512) - 255.5, []
    for full_well in (25_000.0, 200.0):
        part = PartErrors(crosstalk=(0.03, 0.03), calibration_rows=256, full_well_e=full_well, read_noise_e=0.0)
        a_hat = crosstalk_ratios(part, cols)[2]
        scatter.append(np.std(a_hat - sensor_crosstalk(part).calibrate(cols, 256, "none")[0]))
    assert scatter[1] / scatter[0] == pytest.approx(np.sqrt(25_000 / 200), rel=0.15)


def test_a_measured_cameras_crop_is_the_files_ratios_at_its_columns_jittered_by_their_errors():
    """measured_crop: scene k of n reads the file's ratios at the columns its crop spans (centred on the crop's
    place across the sensor: the middle scene on the sensor's middle column); they unmix it, and the true
    ratios are them plus one draw of their standard errors (zero errors: the file's ratios themselves)."""
    from doefab.errors import DoefabError
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    w, size = 1000, 64
    a, b = 0.01 + 1e-5 * np.arange(w), 0.2 - 1e-5 * np.arange(w)
    exact = DualPixelCrosstalk(a, b, (a, b))
    exact.standard_error = (np.zeros(w), np.zeros(w))
    got = C.measured_crop(exact, 1, 3, size, np.random.default_rng(0))  # the middle of three scenes
    first = int(np.argmin(np.abs(got.estimate[0][0] - a)))
    assert first == w // 2 - size // 2 and np.array_equal(got.estimate[0], a[first:first + size])
    assert np.array_equal(got.estimate[1], b[first:first + size])
    assert np.array_equal(got.alpha_lr, got.estimate[0]) and np.array_equal(got.alpha_rl, got.estimate[1])
    left = C.measured_crop(exact, 0, 3, size, np.random.default_rng(0))  # the first scene: 40 % of w to the left
    assert int(np.argmin(np.abs(left.estimate[0][0] - a))) == pytest.approx(first - 0.4 * w, abs=1)
    noisy = DualPixelCrosstalk(a, b, (a, b))
    noisy.standard_error = (np.full(w, 1e-3), np.full(w, 2e-3))
    got = C.measured_crop(noisy, 1, 3, 512, np.random.default_rng(1))
    assert np.std(got.alpha_lr - got.estimate[0]) == pytest.approx(1e-3, rel=0.15)
    assert np.std(got.alpha_rl - got.estimate[1]) == pytest.approx(2e-3, rel=0.15)
    with pytest.raises(DoefabError, match="1000 columns: a 1024-px scene"):
        C.measured_crop(exact, 0, 1, 1024, np.random.default_rng(0))


def test_measured_conditions_with_a_camera_use_it_for_every_scene_and_say_so():
    from doefab.imaging.crosstalk import DualPixelCrosstalk

    w = 300
    cam = DualPixelCrosstalk(np.full(w, 0.1), np.full(w, 0.05), (np.full(w, 0.1), np.full(w, 0.05)))
    pair = doefab.split_aperture_psf(None, doefab.Camera(doe_pixels=64, doe_pitch=135e-6), [550e-9],
                                     [float("inf")], kernel_size=21)
    cond = C.measured(pair, "val", camera=cam)
    xt = cond.crosstalk_for(0, 2, 64)
    assert np.allclose(xt.estimate[0], 0.1) and np.allclose(xt.alpha_rl, 0.05)
    d = cond.describe()
    assert d["crosstalk_source"] == "measured" and d["budget_sha256"] is None and len(d["crosstalk_sha256"]) == 16
    assert C.measured(pair, "val").describe().get("crosstalk_source") is None  # the budget's sensor otherwise


def test_the_budget_digest_tells_budgets_apart_and_is_what_honest_captures_record(monkeypatch):
    """``budget_sha256``: the shipped budget's by default; another value anywhere gives another digest; the record
    of which defaults were used does not count; ``honest`` conditions carry the same digest."""
    import copy

    from doefab.tolerance import conditions as cond
    from doefab.tolerance.errors import load_budget

    budget = load_budget()
    assert cond.budget_sha256() == cond.budget_sha256(budget) and len(cond.budget_sha256()) == 16
    other = copy.deepcopy(budget)
    other["mounting"]["tilt_sigma_deg"] = float(other["mounting"].get("tilt_sigma_deg", 0.0)) + 0.01
    assert cond.budget_sha256(other) != cond.budget_sha256(budget)
    assert cond.budget_sha256({**budget, "defaults_used": ["anything"]}) == cond.budget_sha256(budget)
    monkeypatch.setattr(cond, "_parts", lambda task, d, split, n, budget, progress: [])  # no PSFs computed here
    assert cond.honest("hdr", "unused", "val", budget=other).budget_sha256 == cond.budget_sha256(other)
