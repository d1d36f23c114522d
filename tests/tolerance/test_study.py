"""Tolerance studies on a small design: crosstalk calibration, reproducible Monte Carlo on every backend,
resume, summary statistics, and the command."""

import json

import numpy as np
import pytest

import doefab
from doefab.cli import main
from doefab.design.design import Design
from doefab.tolerance import montecarlo, study, yieldstats
from doefab.tolerance.errors import PartErrors, load_budget


def test_a_noisy_calibration_leaves_its_own_error_and_what_it_cannot_hold(design_dir):
    """Uncalibrated crosstalk costs; calibrated, the coded view is what the 2 × 2 algebra of Eq. 29 predicts for
    the estimated ratios (here written with numpy's inverse): the nominal view plus the calibration's error
    times the two halves. The calibration's noise shrinks with its rows; what a per-column calibration cannot
    hold of the sensor's true crosstalk (its row's variation, the session's drift) stays."""
    from doefab.tolerance.errors import crosstalk_ratios, sensor_crosstalk

    j = study.judge_for(str(design_dir), 1)
    coded, plain = j.nominal, j.uncoded()
    assert j.evaluate(PartErrors(crosstalk=(0.1, 0.1), calibrated=False))["l1_to_nominal"] > 0.01
    gaps = []
    for rows in (4, 64, 4096):
        err = PartErrors(crosstalk=(0.1, 0.06), calibrated=True, calibration_rows=rows, seed=3)
        a, b, a_hat, b_hat = (float(v[0]) for v in crosstalk_ratios(err, [0.0]))
        mix = np.array([[1 - a, b], [a, 1 - b]])  # (left, right) recorded from (plain, coded)
        k = np.linalg.inv(np.array([[1 - a_hat, b_hat], [a_hat, 1 - b_hat]])) @ mix
        predicted = k[1, 0] * plain + k[1, 1] * coded
        got = j.coded_view(coded, err)
        assert float((got - predicted).abs().max()) < 1e-6 * float(coded.max())
        a_ref, b_ref = (float(v[0]) for v in sensor_crosstalk(err).calibrate([0.0], rows, "none"))
        gaps.append(abs(a_hat - a_ref) + abs(b_hat - b_ref))  # the calibration's noise
        assert abs(a - a_ref) + abs(b - b_ref) > 1e-3  # the true crosstalk's residual
        bound = abs(k[1, 0]) * float(plain.abs().sum()) + abs(k[1, 1] - 1) * float(coded.abs().sum())
        assert float((got - coded).abs().sum()) <= bound * (1 + 1e-9)
    assert gaps[0] > gaps[2] > 0  # more rows, a less noisy estimate


def test_same_seed_same_numbers_in_process_pool_and_dask(design_dir, tmp_path):
    budget = load_budget()
    a = montecarlo.monte_carlo(design_dir, budget, 4, tmp_path / "a", seed=7, progress=False)
    b = montecarlo.monte_carlo(design_dir, budget, 4, tmp_path / "b", seed=7, workers=2, progress=False)
    pytest.importorskip("dask.distributed")
    c = montecarlo.monte_carlo(design_dir, budget, 4, tmp_path / "c", seed=7, scheduler="local:2", progress=False)
    key = lambda rows: [(r["index"], r["metric"], r["worst"], r["l1_to_nominal"], r["errors"]) for r in rows]  # noqa: E731
    assert key(a) == key(b) == key(c)
    d = montecarlo.monte_carlo(design_dir, budget, 4, tmp_path / "d", seed=8, progress=False)
    assert key(d) != key(a)


def test_interrupted_study_resumes(design_dir, tmp_path):
    budget = load_budget()
    full = montecarlo.monte_carlo(design_dir, budget, 4, tmp_path / "full", seed=1, progress=False)
    part = tmp_path / "part"
    montecarlo.monte_carlo(design_dir, budget, 4, part, seed=1, progress=False)
    lines = (part / "samples.jsonl").read_text().splitlines()
    (part / "samples.jsonl").write_text("\n".join(lines[:2]) + "\n" + lines[2][:20])  # killed mid-write
    again = montecarlo.monte_carlo(design_dir, budget, 4, part, seed=1, progress=False)
    assert [r["metric"] for r in again] == [r["metric"] for r in full]
    rows = [json.loads(line) for line in (part / "samples.jsonl").read_text().splitlines()]  # JSON lines still
    assert sorted(r["index"] for r in rows[1:]) == [0, 1, 2, 3]  # the cut line gone, no row glued to it


def test_parts_scored_on_another_metric_are_not_resumed_into_a_study(design_dir, tmp_path, monkeypatch):
    """The task's metric lives outside the part model's code: a study whose parts were scored on other pixels (the
    streak's cross with its centre) is refused on resume, naming the metric, as one on another budget is."""
    from doefab.errors import DoefabError
    from doefab.tasks.streak import StreakTask

    budget = load_budget()
    montecarlo.monte_carlo(design_dir, budget, 2, tmp_path, seed=1, progress=False)
    monkeypatch.setattr(StreakTask, "band_masks", lambda self, cam: self._cross(self.band_px)[None, None])
    with pytest.raises(DoefabError, match="differs in metric_sha256"):
        montecarlo.monte_carlo(design_dir, budget, 2, tmp_path, seed=1, progress=False)
    monkeypatch.undo()
    assert len(montecarlo.monte_carlo(design_dir, budget, 2, tmp_path, seed=1, progress=False)) == 2


def test_the_part_log_is_strict_json_and_a_nan_metric_resumes_as_nan(design_dir, tmp_path, monkeypatch):
    """samples.jsonl is read by jq and browsers too: a part whose metric is undefined is written as "nan", not as
    the NaN that strict readers refuse, and a resumed run reads it back as a float NaN, not as text."""
    import math

    def nan_part(*args, **kw):
        return {"metric": math.nan, "worst": -math.inf, "l1_to_nominal": 0.0}

    monkeypatch.setattr(study, "evaluate_part", nan_part)
    out = tmp_path / "nan"
    montecarlo.monte_carlo(design_dir, load_budget(), 2, out, seed=1, progress=False)

    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")

    lines = (out / "samples.jsonl").read_text().splitlines()
    rows = [json.loads(line, parse_constant=refuse) for line in lines]
    assert len(rows) == 3 and rows[1]["metric"] == "nan" and rows[1]["worst"] == "-inf"
    (out / "samples.jsonl").write_text("\n".join(lines[:2]) + "\n")  # the second part lost: resumed
    again = montecarlo.monte_carlo(design_dir, load_budget(), 2, out, seed=1, progress=False)
    assert all(isinstance(r["metric"], float) and math.isnan(r["metric"]) for r in again)
    assert all(r["worst"] == -math.inf for r in again)


def test_summary_statistics():
    rows = [{"metric": m, "worst": m, "l1_to_nominal": 0.0} for m in (0.4, 0.6, 0.6, 0.8)]
    s = yieldstats.summarize(rows, {"hdr": {"psf_metric_min": 0.5}}, "hdr", {"psf": {"psf_metric": 0.9}})
    assert s["metric"]["mean"] == pytest.approx(0.6)
    from scipy.stats import t

    half = t.ppf(0.975, 3) * np.std([0.4, 0.6, 0.6, 0.8], ddof=1) / 2  # Student's t: 3.18, not 1.96, at 4 parts
    assert s["metric"]["ci95"] == pytest.approx([0.6 - half, 0.6 + half])
    two = yieldstats.mean_ci([0.4, 0.6])["ci95"]  # two parts: t = 12.7 at one degree of freedom
    assert two == pytest.approx([0.5 - 12.7062 * 0.1, 0.5 + 12.7062 * 0.1], rel=1e-5)
    assert all(np.isnan(yieldstats.mean_ci([0.4, float("nan")])["ci95"]))  # one part left: no interval
    left_out = yieldstats.mean_ci([float("inf"), 1.0, 2.0, float("nan")])  # what the mean is of, said
    assert (left_out["n"], left_out["n_not_finite"], left_out["mean"]) == (2, 2, 1.5)
    assert (s["metric"]["n"], s["metric"]["n_not_finite"]) == (4, 0)
    # three parts near the top: t's interval, mean ± 4.30 · sd / √3, reaches past the fraction's 1 and is cut there
    near = [{"metric": m, "worst": m, "l1_to_nominal": 0.01} for m in (0.99, 0.98, 0.80)]
    top = yieldstats.summarize(near, {"hdr": {"psf_metric_min": 0.5}}, "hdr", {"psf": {"psf_metric": 0.9}})
    reach = np.mean([0.99, 0.98, 0.80]) + t.ppf(0.975, 2) * np.std([0.99, 0.98, 0.80], ddof=1) / np.sqrt(3)
    assert reach > 1 and top["metric"]["ci95"][1] == 1.0 and top["l1_to_nominal"]["ci95"] == [0.01, 0.01]
    network = [{"metric": 0.9, "worst": 0.9, "l1_to_nominal": 0.0, "network": {"n": {"psnr": p}}}
               for p in (99.0, 99.5, 80.0)]
    psnr = yieldstats.summarize(network, {"hdr": {"psf_metric_min": 0.5}}, "hdr", {"psf": {"psf_metric": 0.9}})
    assert psnr["network"]["n"]["metrics"]["psnr"]["ci95"][1] == 100.0  # a PSNR's span: 0–100 dB
    assert s["yield"]["value"] == 0.75 and 0 < s["yield"]["ci95"][0] < 0.75 < s["yield"]["ci95"][1] <= 1
    # relative limit: at most 0.25 below the nominal 0.9 → 0.65: two of four parts pass
    s = yieldstats.summarize(rows, {"hdr": {"psf_metric_loss_max": 0.25}}, "hdr", {"psf": {"psf_metric": 0.9}})
    assert s["yield"]["value"] == 0.25


def test_wilson_interval_against_its_formula_and_at_the_edges():
    lo, hi = yieldstats.wilson(24, 24)
    assert hi == 1.0 and lo == pytest.approx(24 / (24 + 1.96**2), rel=1e-9)  # all pass: (n/(n + z²), 1)
    lo, hi = yieldstats.wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(1.96**2 / (10 + 1.96**2), rel=1e-9)
    lo, hi = yieldstats.wilson(5, 10)
    assert lo < 0.5 < hi and hi - 0.5 == pytest.approx(0.5 - lo)


def test_command_writes_json_report_and_plots(design_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["tolerance", "--design", str(design_dir), "--samples", "3", "--sweep", "--levels", "--surrogate",
                 "--out", str(out)]) == 0
    res = json.loads((out / "tolerance.json").read_text())
    assert len(res["samples"]) == 3 and "yield" in res["summary"] and res["tornado"]
    assert [r["levels"] for r in res["quantization"]] == ["continuous", 16, 8, 4, 2]
    assert res["grid"]["monte_carlo_grid"] in (1, 2, 4, 8) and res["grid"]["kinds"]
    # the surrogate: its base is the base part judged directly, and at the parameter that moves the metric most
    # its prediction from that part's own features is the directly judged metric (the fit's ±h points)
    from doefab.tolerance.surrogate import base_part, features, parameters, predict

    model, budget = res["surrogate"]["model"], load_budget()
    judge = study.judge_for(str(design_dir), res["grid"]["monte_carlo_grid"])
    base = base_part(budget).for_masks(judge.n_masks)
    assert model["base"] == pytest.approx(judge.evaluate(base)["metric"], rel=1e-9)
    params = parameters(budget, judge.chain, judge.n_masks, model["gap"])
    j = int(np.argmax(np.abs(model["a"]) * model["h"] + np.abs(model["b"]) * np.square(model["h"])))
    name, h, set_ = params[j].name, params[j].h, params[j].set
    assert name == model["names"][j] and abs(model["a"][j]) + abs(model["b"][j]) > 0
    for x in (h, -h):
        part = set_(base, x)
        direct = judge.evaluate(part)["metric"]
        assert predict(model, features(part, budget, judge.chain, judge.n_masks, model["gap"])) == pytest.approx(
            direct, rel=1e-6, abs=1e-12), name
    # 3 direct parts are too few to validate on: it is checked on 16 held-out parts of its own
    v = res["surrogate"]["validation"]
    assert v["n"] == 16 and v["parts"] == "held-out parts of its own" and model["calibration"]["n"] == 16
    text = (out / "report.md").read_text()
    assert f"surrogate − direct yield {v['yield_difference']:+.3f}" in text
    assert "Yield at PSF level" in text and "Would buy the most" in text
    for f in ("report.md", "sweeps.png", "tornado.png", "quantization.png", "yield_vs_n.png"):
        assert (out / f).stat().st_size > 500


def test_bad_budget_lists_every_problem(tmp_path):
    from doefab.errors import DoefabError

    p = tmp_path / "b.toml"
    p.write_text("[overlay]\nshift_sigma_um = 'big'\nshift_sigma_mm = 1\n[etch]\nrandom_sigma_percent = 500\n")
    with pytest.raises(DoefabError) as exc:
        load_budget(p)
    msg = str(exc.value)
    assert "overlay.shift_sigma_um must be a number" in msg and "unknown key overlay.shift_sigma_mm" in msg
    assert "etch.random_sigma_percent = 500" in msg


def _holder_json(path, clearance=0.25, doe_to_lens=1.6, passed=True):
    path.write_text(json.dumps({"parameters": {"clearance_mm": clearance, "die_width_mm": 12.0, "die_height_mm": 12.0},
                                "checks": {"passed": passed, "die_to_pocket_gap_mm": clearance,
                                           "doe_to_lens_mm": doe_to_lens}}))
    return path


def test_mounting_ranges_come_from_the_holder(tmp_path):
    from doefab.tolerance.errors import holder_mounting

    m = holder_mounting(_holder_json(tmp_path / "holder.json", clearance=0.4, doe_to_lens=2.2))
    assert m["decenter_max_mm"] == 0.4 and m["axial_gap_mm"] == 2.2
    # a 12 mm square die turns until a corner meets the pocket wall: a (cos θ + sin θ) = a + c, θ ≈ c / a
    theta = np.radians(4 * m["rotation_sigma_deg"])
    assert 6 * (np.cos(theta) + np.sin(theta)) == pytest.approx(6.4, rel=0.01)
    with pytest.raises(doefab.DoefabError, match="failed its checks"):
        holder_mounting(_holder_json(tmp_path / "bad.json", passed=False))
    with pytest.raises(doefab.DoefabError, match="no holder.json"):
        holder_mounting(tmp_path / "missing")


def test_sampled_parts_carry_the_budget_gap():
    from doefab.tolerance.errors import sample_errors

    budget = load_budget()
    gaps = [sample_errors(budget, np.random.default_rng(i), n_masks=4).axial_gap for i in range(200)]
    from holder_cad.params import HolderParams

    # the budget's gap is the default holder's (its DOE-to-glass distance; the pupil at the glass by default)
    assert np.mean(gaps) == pytest.approx(HolderParams().doe_to_lens_mm * 1e-3, abs=3e-5)
    assert 0.05e-3 < np.std(gaps) < 0.15e-3


def test_resume_refuses_samples_of_another_run(design_dir, tmp_path):
    budget = load_budget()
    montecarlo.monte_carlo(design_dir, budget, 2, tmp_path / "r", seed=1, progress=False)
    with pytest.raises(doefab.DoefabError, match="written for another run.*seed"):
        montecarlo.monte_carlo(design_dir, budget, 3, tmp_path / "r", seed=2, progress=False)
    other = {**budget, "overlay": {**budget["overlay"], "shift_sigma_um": 1.0}}
    with pytest.raises(doefab.DoefabError, match="budget_sha256"):
        montecarlo.monte_carlo(design_dir, other, 3, tmp_path / "r", seed=1, progress=False)
    assert len(montecarlo.monte_carlo(design_dir, budget, 3, tmp_path / "r", seed=1, progress=False)) == 3


def test_a_partial_budget_takes_the_defaults_and_lists_them(tmp_path):
    """Issue 21, row 4: an empty budget file is the default budget, every key listed as taken from it."""
    p = tmp_path / "e.toml"
    p.write_text("")
    b = load_budget(p)
    assert b["mounting"] == load_budget()["mounting"] and "mounting.decenter_max_mm" in b["defaults_used"]
    p.write_text("[overlay]\nshift_sigma_um = 2.0\n")
    b = load_budget(p)
    assert b["overlay"]["shift_sigma_um"] == 2.0 and "overlay.shift_sigma_um" not in b["defaults_used"]
    assert "overlay.rotation_sigma_urad" in b["defaults_used"]


def test_specs_are_per_task_and_a_spec_the_design_cannot_meet_is_said(design_dir, tmp_path):
    """Issue 21, row 5: the depth design's own nominal must not fall under a global limit silently."""
    from doefab.tolerance.report import run_study

    p = tmp_path / "b.toml"
    p.write_text("[spec.hdr]\npsf_metric_min = 0.99\n")
    res = run_study(design_dir, load_budget(p), tmp_path / "o", samples=2, grid=1, progress=False)
    assert any("nominal part already fails" in w and "psf_metric_min" in w for w in res["warnings"])
    assert res["summary"]["yield"]["value"] == 0.0
    text = (tmp_path / "o" / "report.md").read_text()
    assert "Warning" in text and "0.99" in text


def test_the_yield_band_is_wilsons_everywhere(design_dir, tmp_path):
    """Issue 21, row 6: when every part passes, Wald's band collapses to zero width at 1.0; Wilson's does not,
    and the table and the figure use the same interval."""
    from doefab.tolerance.report import run_study

    p = tmp_path / "b.toml"
    # no crosstalk: its calibrated residual can take this toy design's near-zero metric below 0
    p.write_text("[sensor]\ncrosstalk_lr_percent = 0.0\ncrosstalk_rl_percent = 0.0\n[spec.hdr]\npsf_metric_min = 0.0\n")
    res = run_study(design_dir, load_budget(p), tmp_path / "w", samples=5, grid=1, progress=False)
    conv = res["convergence"][-1]
    assert conv["yield"] == 1.0 and conv["yield_ci95"] == pytest.approx(list(yieldstats.wilson(5, 5)))
    assert conv["yield_ci95"][0] < 0.6 and res["summary"]["yield"]["ci95"] == conv["yield_ci95"]
    assert (tmp_path / "w" / "yield_vs_n.png").stat().st_size > 1000


def test_the_yield_figure_draws_wilsons_band_for_every_n(tmp_path, monkeypatch):
    """Issue 21, row 6: the band drawn in yield_vs_n.png is the Wilson interval of each running count (the
    figure's own fill, read back from matplotlib), never Wald's zero-width band at 0 or 1."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.axes import Axes

    from doefab.tolerance import plots

    drawn = {}
    real = Axes.fill_between

    def spy(self, x, y1, y2=0, **kw):
        drawn.update(x=np.asarray(x), lo=np.asarray(y1), hi=np.asarray(y2))
        return real(self, x, y1, y2, **kw)

    monkeypatch.setattr(Axes, "fill_between", spy)
    ok = [True, True, True, False, True, True]
    plots.yield_plot(tmp_path / "y.png", ok, "spec")
    k = np.cumsum(ok)
    want = np.array([yieldstats.wilson(int(a), n + 1) for n, a in enumerate(k)])
    assert np.allclose(drawn["lo"], want[:, 0]) and np.allclose(drawn["hi"], want[:, 1])
    assert drawn["hi"][0] - drawn["lo"][0] > 0.5  # one passing part: Wilson is wide, Wald would be 0


def _refuse(constant):
    raise ValueError(f"{constant} is not JSON: a browser's JSON.parse refuses it")


def test_quantization_rows_say_what_they_were_quantized_from(design_dir):
    rows = study.quantization_study(design_dir, levels=(None, 16, 8))
    assert rows[0]["levels"] == "continuous" and "n/a" in rows[0]["source"]  # this folder has no continuous design
    assert rows[1]["source"] == "the committed 16-level map" and "re-quantized" in rows[2]["source"]


def test_auto_workers_one_per_core_only_when_parts_repay_the_start_up(monkeypatch):
    monkeypatch.setattr(montecarlo.os, "sched_getaffinity", lambda pid: {0, 1, 2}, raising=False)
    assert montecarlo.auto_workers(12) == 3  # 4 parts per core
    assert montecarlo.auto_workers(11) == 1  # too few to repay three workers' start-up
    monkeypatch.setattr(montecarlo.os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert montecarlo.auto_workers(300) == 1


def test_freed_memory_is_kept_in_a_judging_process():
    import ctypes.util

    applied = montecarlo.keep_freed_memory()
    assert applied == (ctypes.util.find_library("c") is not None and __import__("platform").libc_ver()[0] == "glibc")


def test_workers_flag_takes_auto_or_a_count():
    from doefab.cli import build_parser

    p = build_parser()
    base = ["tolerance", "--design", "masks/grating", "--out", "x"]
    assert p.parse_args(base).workers is None  # auto by default
    assert p.parse_args(base + ["--workers", "auto"]).workers is None
    assert p.parse_args(base + ["--workers", "3"]).workers == 3
    with pytest.raises(SystemExit):
        p.parse_args(base + ["--workers", "many"])


@pytest.mark.parametrize("design", ["streak", "grating", "half-ring"])
def test_each_committed_design_meets_its_tasks_default_spec(design):
    """Issue 21, row 5: the shipped budget's per-task PSF limit lies below what each committed design's
    fabricated relief reaches — the nominal part's PSF metric as the tolerance study computes it (its judge, here
    run afresh), which is the quantized metric design.json records — so the main job's yield is not zero by
    construction."""
    from doefab.design.committed import committed_dir
    from doefab.tolerance.spec import TASK_OF_DESIGN, nominal_failures

    judge = study.judge_for(str(committed_dir(design)), 1)
    nominal = judge.score(judge.nominal)["metric"]
    task = TASK_OF_DESIGN[judge.design.task]
    spec = load_budget()["spec"]
    assert nominal == pytest.approx(Design.load(committed_dir(design)).metrics["quantized"], abs=1e-6)
    assert spec[task]["psf_metric_min"] < nominal and nominal_failures(spec, task, "psf", {"psf_metric": nominal}) == []


def test_a_limit_between_two_parts_passes_the_better_and_fails_the_worse():
    """Two parts of the committed streak design judged here, the error-free one (0.869) and one decentred 0.25 mm
    across the split (0.796): an absolute limit half-way between their PSF metrics, or a loss margin of half their
    difference, passes the first and fails the second (and a nominal part under the limit is said to fail it);
    the two parts yield 1/2."""
    from doefab.design.committed import committed_dir
    from doefab.tolerance.spec import meets, nominal_failures

    judge = study.judge_for(str(committed_dir("streak")), 1)
    good = judge.score(judge.nominal)["metric"]
    bad = judge.evaluate(PartErrors(mount_shift=(250e-6, 0.0)))["metric"]
    assert good - bad > 0.05  # two parts the limits can tell apart
    nominal = {"psf_metric": good}
    for table in ({"psf_metric_min": (good + bad) / 2}, {"psf_metric_loss_max": (good - bad) / 2}):
        spec = {"hdr": table}
        assert [meets({"psf_metric": m}, spec, "hdr", "psf", nominal) for m in (good, bad)] == [True, False], table
        rows = [{"metric": m, "worst": m, "l1_to_nominal": 0.0} for m in (good, bad)]
        assert yieldstats.summarize(rows, spec, "hdr", {"psf": nominal})["yield"]["value"] == 0.5
    spec = {"hdr": {"psf_metric_min": (good + bad) / 2}}
    assert nominal_failures(spec, "hdr", "psf", nominal) == []
    assert nominal_failures(spec, "hdr", "psf", {"psf_metric": bad}) != []


def _known_surrogate_metric(hs: dict, cubic: float):
    """A metric with a known expansion in the surrogate's parameters: 0.9 + 0.02 u₂ − 0.05 u₁² + ``cubic`` u₁³
    − 0.04 d² − 0.02 e + 0.01 r², each u = x / h its parameter over its step (etch depth of masks 1 and 2,
    decenter across the split, edge bias, mount rotation); the rest leave it alone."""
    def metric(part: PartErrors) -> float:
        u1 = (part.depth_scale[0] - 1) / hs["etch depth, mask 1"]
        u2 = (part.depth_scale[1] - 1) / hs["etch depth, mask 2"]
        d = part.mount_shift[0] / hs["decenter across split"]
        e = part.edge_bias / hs["edge bias"]
        r = part.mount_rotation / hs["mount rotation"]
        return 0.9 + 0.02 * u2 - 0.05 * u1**2 + cubic * u1**3 - 0.04 * d**2 - 0.02 * e + 0.01 * r**2
    return metric


def test_the_surrogate_recovers_a_known_expansion_and_its_yield():
    """On a metric whose expansion is known, the surrogate's coefficients are that expansion (a_j, b_j of each
    parameter over its step h_j; a cubic term c u³ adds c/h to the slope, as central differences at ±h do), its
    largest losses are judged at more points (a cubic's among them), and its yield on a quadratic metric is the
    fraction of its own draws whose metric, computed directly, meets the limit."""
    from doefab.tolerance.errors import sample_errors
    from doefab.tolerance.surrogate import calibrate, fit_surrogate, parameters, predict, surrogate_yield

    budget, chain = load_budget(), {1: 0, 2: 0, 3: 0, 4: 0}
    hs = {p.name: p.h for p in parameters(budget, chain, 4)}
    quad = _known_surrogate_metric(hs, cubic=0.0)
    model = fit_surrogate(quad, budget, chain, False, n_masks=4)
    want = {name: (0.0, 0.0) for name in hs}
    want.update({"etch depth, mask 1": (0.0, -0.05), "etch depth, mask 2": (0.02, 0.0),
                 "decenter across split": (0.0, -0.04), "edge bias": (-0.02, 0.0), "mount rotation": (0.0, 0.01)})
    got = {n: (a * h, b * h * h) for n, h, a, b in zip(model["names"], model["h"], model["a"], model["b"])}
    assert model["base"] == pytest.approx(0.9) and got.keys() == want.keys()
    for name, (a, b) in want.items():
        assert got[name] == pytest.approx((a, b), abs=1e-9), name
    cubic = fit_surrogate(_known_surrogate_metric(hs, cubic=0.03), budget, chain, False, n_masks=4)
    assert cubic["a"][0] * hs["etch depth, mask 1"] == pytest.approx(0.03, abs=1e-9)  # c/h · h
    curve = cubic["curves"]["etch depth, mask 1"]  # its largest loss: judged at more points, cubic term and all
    assert curve["metric"] == pytest.approx([0.9 - 0.05 * u**2 + 0.03 * u**3 for u in curve["u"]], abs=1e-12)
    # a quadratic metric fitted without curves, calibrated on parts of it: the line is m = m̂ with no scatter, and
    # the yield is the draws' own (the same children the surrogate draws)
    children = np.random.SeedSequence(5).spawn(12)
    held = [sample_errors(budget, np.random.default_rng(c), n_masks=4) for c in children]
    plain = calibrate(fit_surrogate(quad, budget, chain, False, n_masks=4, refine=float("inf")), budget, chain,
                      [(p, quad(p)) for p in held], n_masks=4)
    cal = plain["calibration"]
    assert (cal["alpha"], cal["beta"], cal["rmse"]) == pytest.approx((0.0, 1.0, 0.0), abs=1e-9)
    y = surrogate_yield(plain, budget, chain, 0.88, draws=500, n_masks=4)
    draws = [quad(sample_errors(budget, np.random.default_rng(c), n_masks=4).for_masks(4))
             for c in np.random.SeedSequence(12345).spawn(500)]
    assert y["value"] == pytest.approx(np.mean(np.array(draws) >= 0.88), abs=1e-12)
    assert 0.05 < y["value"] < 0.95  # a limit inside the spread, so the count can be wrong
    assert predict(model, np.zeros(len(hs))) == pytest.approx(0.9)


def test_an_empty_budget_file_at_the_command_line_reports_the_defaults_it_took(design_dir, tmp_path, capsys):
    """Issue 21, row 4, replayed: ``: > e.toml; doefab tolerance --budget e.toml --samples 1``: the default budget's
    values (not zeros), every key taken from it listed in the output and the report, no "nan–nan" interval."""
    e = tmp_path / "e.toml"
    e.write_text("")
    rc = main(["tolerance", "--design", str(design_dir), "--budget", str(e), "--samples", "1", "--grid", "1",
               "--out", str(tmp_path / "te")])
    out = capsys.readouterr().out
    assert rc == 0
    res = json.loads((tmp_path / "te" / "tolerance.json").read_text(), parse_constant=_refuse)  # strict JSON
    assert res["summary"]["metric"]["ci95"] == ["nan", "nan"]  # one part: no interval, written as scene files do
    assert res["budget"]["overlay"] == load_budget()["overlay"]  # not zeros
    report = (tmp_path / "te" / "report.md").read_text()
    for text in (out, report):
        assert "taken from the default budget" in text and "mounting.decenter_max_mm" in text
        assert "nan" not in text.lower().replace("nanometre", "") and "fewer than two parts" in text


def test_run_study_reuses_its_steps_only_for_the_same_study(design_dir, tmp_path, monkeypatch):
    """Issue 21, row 10, through ``run_study``: an interrupted study rerun with the same design and budget reuses
    its grid study and tornado (the tornado is not computed again, the report says so); a changed budget, a
    changed grid or another design computes them afresh."""
    from doefab.tolerance.report import run_study

    calls = []
    real = study.tornado
    monkeypatch.setattr(study, "tornado", lambda *a, **k: calls.append(1) or real(*a, **k))
    out = tmp_path / "o"
    run_study(design_dir, load_budget(), out, samples=0, grid=1, progress=False)
    res = run_study(design_dir, load_budget(), out, samples=0, grid=1, progress=False)
    assert len(calls) == 1 and "tornado" in res["steps_reused"]
    assert "Reused from an earlier run of the same study" in (out / "report.md").read_text()
    other = tmp_path / "b.toml"
    other.write_text("[overlay]\nshift_sigma_um = 1.5\n")
    run_study(design_dir, load_budget(other), out, samples=0, grid=1, progress=False)
    assert len(calls) == 2
    run_study(design_dir, load_budget(other), out, samples=0, grid=2, progress=False)
    assert len(calls) == 3


def test_a_resumed_study_reuses_its_finished_steps_and_a_changed_one_does_not(tmp_path):
    """Issue 21, row 10: a study's finished steps (grid study, tornado) are kept with the key of their run; a
    resumed run of the same key reuses them, a run of another key computes afresh."""
    from doefab.tolerance.report import cached_step

    calls = []
    key = {"design_levels_sha256": "a", "budget_sha256": "b"}
    assert cached_step(tmp_path, "tornado", key, lambda: calls.append(1) or [{"error": "x"}]) == [{"error": "x"}]
    assert cached_step(tmp_path, "tornado", dict(key), lambda: calls.append(2) or []) == [{"error": "x"}]
    assert calls == [1]
    assert cached_step(tmp_path, "tornado", {**key, "budget_sha256": "c"}, lambda: calls.append(3) or []) == []
    assert calls == [1, 3]


def test_what_limits_a_part_is_ranked_by_what_it_delivers():
    """Issue 22, item 4: where the tornado judged errors through the network, "limited by" and "would buy the
    most" follow the delivered primary metric (here highlight PSNR), not the PSF metric's order."""
    from doefab.tolerance.report import REMEDY, summary_lines

    def row(name, delta, dpsnr):
        return {"error": name, "value": 1.0, "unit": "µm", "grid": 1, "metric": 0.8 + delta, "delta": delta,
                "network_delta": {"nominal_psf": {"psnr_highlight": dpsnr, "psnr": 0.0},
                                  "measured_psf": {"psnr_highlight": dpsnr / 2, "psnr": 0.0}}}

    res = {"task": "hdr", "stop": "the DOE", "warnings": [], "budget": {}, "nominal": {"psf": {"psf_metric": 0.8}},
           "spec": {"psf": None, "network": None},
           "tornado": [row("mask overlay", -0.06, -0.2), row("decenter across split", -0.05, -1.5),
                       row("edge bias", -0.01, 0.1)]}
    text = "\n".join(summary_lines(res))
    assert text.index("decenter across split") < text.index("mask overlay")
    assert "edge bias" not in text.split("Would buy")[0]  # it delivers better: not a limit
    assert REMEDY["decenter across split"] in text and "1.5 dB" in text


def test_a_budget_judges_the_crosstalk_pipeline_it_describes():
    from doefab.tolerance.kinds import kind

    cal = load_budget()
    assert cal["sensor"].get("calibrated", True)
    assert kind("crosstalk, calibrated").from_budget(cal) > 0 and kind("crosstalk, uncalibrated").from_budget(cal) == 0
    raw = {**cal, "sensor": {**cal["sensor"], "calibrated": False}}
    assert kind("crosstalk, uncalibrated").from_budget(raw) > 0 and kind("crosstalk, calibrated").from_budget(raw) == 0


def test_the_surrogate_has_a_gap_parameter_only_where_the_lens_is_the_stop():
    from dataclasses import replace

    from doefab.tolerance.errors import nominal_gap
    from doefab.tolerance.surrogate import base_part, features, parameters

    budget = load_budget()
    chain = {1: 0, 2: 0, 3: 0, 4: 0}
    names = [p[0] for p in parameters(budget, chain, 4)]
    assert "axial gap" not in names
    with_gap = parameters(budget, chain, 4, gap=True)
    g = [p.name for p in with_gap].index("axial gap")
    assert [p.name for p in with_gap[:g] + with_gap[g + 1:]] == names
    assert with_gap[g].h == pytest.approx(2e-3 * budget["mounting"]["axial_gap_sigma_mm"])
    part = replace(base_part(budget), axial_gap=nominal_gap(budget) + 0.3e-3)
    assert features(part, budget, chain, 4, gap=True)[g] == pytest.approx(0.3e-3)
    assert with_gap[g].set(base_part(budget), -0.2e-3).axial_gap == pytest.approx(nominal_gap(budget) - 0.2e-3)


def test_quantization_rows_of_a_design_with_its_continuous_heights_come_from_them(design_dir, tmp_path):
    """Issue 22, item 6: a design written by ``doefab design`` keeps ``height.npy``: its 8/4/2-level rows are
    quantized from those continuous heights (not from the 16-level map), and equal an independent quantization
    of them; the continuous row is their own PSF metric."""
    from doefab.fabrication.levels import quantize_levels

    d = Design.load(design_dir)
    rng = np.random.default_rng(5)
    h2pi = d.camera.material.height_2pi(d.camera.design_wavelength)
    height = np.mod(d.height + rng.normal(0, 0.02 * h2pi, d.height.shape), h2pi)  # off the 16 levels
    cont = Design(**{**d.__dict__, "height": height})
    cont.save(tmp_path / "cont")
    rows = {r["levels"]: r for r in study.quantization_study(tmp_path / "cont", levels=(None, 16, 4))}
    assert rows["continuous"]["source"] == "the continuous design" and np.isfinite(rows["continuous"]["metric"])
    assert rows[4]["source"] == "the continuous design" and rows[16]["source"] == "the continuous design"
    judge = study.judge_for(str(tmp_path / "cont"), 1)
    want = judge.score(judge.psf_from_height(quantize_levels(height, d.camera, 4) * h2pi / 4))["metric"]
    assert rows[4]["metric"] == pytest.approx(want, abs=1e-9)
    from_map = judge.score(judge.psf_from_height(quantize_levels(d.height, d.camera, 4) * h2pi / 4))["metric"]
    assert abs(from_map - want) > 1e-4  # the test can tell the two sources apart


def test_resume_refuses_samples_of_another_design_or_grid(design_dir, tmp_path):
    budget = load_budget()
    montecarlo.monte_carlo(design_dir, budget, 2, tmp_path / "r", seed=1, progress=False)
    with pytest.raises(doefab.DoefabError, match="written for another run.*grid"):
        montecarlo.monte_carlo(design_dir, budget, 3, tmp_path / "r", seed=1, supersample=2, progress=False)
    d = Design.load(design_dir)
    lv = d.levels.copy()
    lv[0, 0] = (int(lv[0, 0]) + 1) % 16
    other = Design(**{**d.__dict__, "levels": lv, "height": doefab.levels_to_height(lv, d.camera)})
    other.save(tmp_path / "other")
    with pytest.raises(doefab.DoefabError, match="written for another run.*design_levels_sha256"):
        montecarlo.monte_carlo(tmp_path / "other", budget, 3, tmp_path / "r", seed=1, progress=False)


def test_for_depth_a_larger_mae_is_the_loss_and_a_nan_is_left_out():
    from doefab.tolerance.report import summary_lines

    def row(name, delta, dmae):
        return {"error": name, "value": 1.0, "unit": "mm", "grid": 1, "metric": 0.4 + delta, "delta": delta,
                "network_delta": {"nominal_psf": {"mae": dmae, "delta125": 0.0},
                                  "measured_psf": {"mae": dmae, "delta125": 0.0}}}

    res = {"task": "depth", "stop": "the DOE", "warnings": [], "budget": {}, "nominal": {"psf": {"psf_metric": 0.4}},
           "spec": {"psf": None, "network": None},
           "tornado": [row("mask overlay", -0.05, 0.01), row("mount rotation", -0.01, float("nan")),
                       row("decenter across split", -0.02, 0.12), row("edge bias", -0.01, -0.02)]}
    text = "\n".join(summary_lines(res))
    limited = text.split("Limited by")[1].split("\n")[0]
    assert limited.index("decenter across split") < limited.index("mask overlay")
    assert "mount rotation" not in limited and "edge bias" not in limited  # NaN and a better MAE: no limit
    assert "0.12 m worse" in limited


def test_a_run_identity_names_the_networks_and_the_alignment_chain(design_dir, tmp_path):
    """Resuming a study's parts with other networks, or on a mask set aligned another way, is another run."""
    import shutil

    from doefab.reconstruction.weights import WEIGHTS_DIR

    d = Design.load(design_dir)
    budget = load_budget()
    a = montecarlo.run_identity(d, budget, 0, 1, False, chain={1: 0, 2: 0})
    assert a != montecarlo.run_identity(d, budget, 0, 1, False, chain={1: 0, 2: 1})
    w = tmp_path / "w"
    w.mkdir()
    for f in ("hdr_proposed.json", "hdr_proposed.pt"):
        shutil.copy(WEIGHTS_DIR / f, w / f)
    shipped = montecarlo.run_identity(d, budget, 0, 1, True)
    assert shipped["network_sha256"] and shipped == montecarlo.run_identity(d, budget, 0, 1, True, w)
    rec = json.loads((w / "hdr_proposed.json").read_text())
    rec["weights_sha256"] = "0" * 64  # retrained weights in the same folder
    (w / "hdr_proposed.json").write_text(json.dumps(rec))
    assert montecarlo.run_identity(d, budget, 0, 1, True, w)["network_sha256"] != shipped["network_sha256"]


def test_the_quantization_study_shows_its_progress(design_dir, monkeypatch):
    """Issue 37, row 20: the quantization study (minutes inside ``doefab run``) has a progress line like the other
    steps: what it does, k of n level counts, and the time left (tqdm's, from the total)."""
    import tqdm

    bars = []

    class Spy:
        def __init__(self, total=None, desc="", unit="it", **kwargs):
            self.total, self.desc, self.counts, self.closed = total, desc, [0], False
            bars.append(self)

        def update(self, n=1):
            self.counts.append(self.counts[-1] + n)

        def set_postfix(self, **kwargs):
            pass

        def close(self):
            self.closed = True

    monkeypatch.setattr(tqdm, "tqdm", Spy)
    rows = study.quantization_study(design_dir, levels=(16, 4), progress=True)
    (bar,) = [b for b in bars if "quantization" in b.desc]
    assert bar.total == len(rows) == 2 and bar.counts == [0, 1, 2] and bar.closed
    bars.clear()
    study.quantization_study(design_dir, levels=(16, 4), progress=False)
    assert bars == []


def test_a_tornado_row_judged_through_the_network_carries_its_scene_noise(design_dir, monkeypatch, tmp_path):
    """Each network-judged tornado row holds its per-scene delivered changes against the error-free part on the same
    scenes, and the study the half-width of the change's 95 % interval from them: the paired t interval (scipy's
    paired t-test), per PSF the network was told and per metric; the report gives it beside the change."""
    from scipy.stats import ttest_rel

    from doefab.tolerance import report

    rng = np.random.default_rng(11)
    base = {"nominal_psf": {"psnr": list(rng.normal(30, 3, 6))}, "measured_psf": {"psnr": list(rng.normal(30, 3, 6))}}
    parts = {}

    def fake(design, s, errors, networks=False, weights_dir=None):
        if errors == PartErrors().to_json():
            scenes = base
        else:  # each error its own per-scene changes
            scenes = parts.setdefault(json.dumps(errors, sort_keys=True), {
                lab: {"psnr": list(np.asarray(v["psnr"]) + rng.normal(-0.3, 0.5, 6))} for lab, v in base.items()})
        return {"metric": 0.8, "network": {lab: {"psnr": float(np.mean(v["psnr"]))} for lab, v in scenes.items()},
                "network_scenes": scenes}

    monkeypatch.setattr(study, "evaluate_part", fake)
    budget = load_budget()
    names = ("mask overlay", "edge bias")
    monkeypatch.setattr(study, "KINDS", [k for k in study.KINDS if k.name in names])
    res = report.run_study(design_dir, budget, tmp_path / "t", samples=0, grid=1, networks=True, progress=False)
    rows = {r["error"]: r for r in res["tornado"]}
    assert set(rows) == set(names) and len(parts) == 2
    for scenes in parts.values():
        (r,) = [r for r in rows.values() if r["network"]["nominal_psf"]["psnr"] == np.mean(scenes["nominal_psf"]["psnr"])]
        for lab in ("nominal_psf", "measured_psf"):
            lo, hi = ttest_rel(scenes[lab]["psnr"], base[lab]["psnr"]).confidence_interval(0.95)
            assert r["network_delta_ci95"][lab]["psnr"] == pytest.approx((hi - lo) / 2, rel=1e-9)
            assert r["network_delta"][lab]["psnr"] == pytest.approx((hi + lo) / 2, rel=1e-9)
    text = (tmp_path / "t" / "report.md").read_text()
    assert f"± {rows['edge bias']['network_delta_ci95']['nominal_psf']['psnr']:.2g} dB" in text


def test_the_quantization_study_through_the_network_shows_what_each_level_count_delivers(design_dir, monkeypatch,
                                                                                          tmp_path):
    """Each level count judged through the network keeps its per-scene values; the report's quantization table gives
    the delivered primary metric and its change from the design's own level count with the paired 95 % interval
    over the scenes (scipy's paired t-test)."""
    from scipy.stats import ttest_rel

    from doefab.tolerance import report
    from doefab.tolerance.netjudge import NetworkJudge

    rng = np.random.default_rng(5)
    judged = []

    class Fake:
        means = staticmethod(NetworkJudge.means)

        def scenes(self, err, height=None):
            vals = rng.normal(29.0 - 0.1 * len(judged), 2.0, 5)
            judged.append(vals)
            told = {"nominal_psf": vals, "measured_psf": vals + rng.normal(0.5, 1.0, 5)}  # each label its own
            return {lab: {"psnr_highlight": list(v), "psnr": list(v + 15.0)} for lab, v in told.items()}

    monkeypatch.setattr(study, "network_judge_for", lambda *a, **k: Fake())
    monkeypatch.setattr(study, "tornado", lambda *a, **k: [])
    monkeypatch.setattr(report, "_step_key", lambda *a, **k: {})
    monkeypatch.setattr(study, "evaluate_part", lambda *a, **k: {"metric": 0.8, "network": {}, "network_scenes": {}})
    res = report.run_study(design_dir, load_budget(), tmp_path / "q", samples=0, grid=1, networks=True,
                           do_levels=True, progress=False)
    rows = {r["levels"]: r for r in res["quantization"]}
    assert list(rows) == ["continuous", 16, 8, 4, 2] and len(judged) == 4  # this folder keeps no continuous design
    assert "network" not in rows["continuous"]
    strict = json.loads((tmp_path / "q" / "tolerance.json").read_text(), parse_constant=_refuse)  # a browser reads it
    assert [strict["quantization"][0][k] for k in ("metric", "worst", "l1_to_nominal")] == [None, None, None]
    ref = rows[16]["network_scenes"]["nominal_psf"]["psnr_highlight"]
    assert "network_delta" not in rows[16]
    for n in (8, 4, 2):
        vals = rows[n]["network_scenes"]["nominal_psf"]["psnr_highlight"]
        lo, hi = ttest_rel(vals, ref).confidence_interval(0.95)
        assert rows[n]["network_delta_ci95"]["nominal_psf"]["psnr_highlight"] == pytest.approx((hi - lo) / 2, rel=1e-9)
        assert rows[n]["network_delta"]["nominal_psf"]["psnr_highlight"] == pytest.approx((hi + lo) / 2, rel=1e-9)
    text = (tmp_path / "q" / "report.md").read_text()
    table = text.split("## Quantization")[1].split("![quantization]")[0]
    assert "| highlight PSNR, network told the nominal PSF | change from 16 levels |" in table
    assert "| n/a: the folder keeps only the 16-level map | — | — | — | — | — | — | — |" in table
    assert "The change columns are empty" not in table
    cells = []
    for lab in ("nominal_psf", "measured_psf"):  # the primary metric (highlight PSNR), nominal PSF first
        d, ci = rows[4]["network_delta"][lab], rows[4]["network_delta_ci95"][lab]
        cells.append(f" {rows[4]['network'][lab]['psnr_highlight']:.2f} dB | {d['psnr_highlight']:+.3g} ± "
                     f"{ci['psnr_highlight']:.2g} dB |")
    (line,) = [x for x in table.splitlines() if x.startswith("| 4 |")]
    assert line.endswith("".join(cells)) and line.count("|") == 10
    (sep,) = [x for x in table.splitlines() if x.startswith("| ---")]
    assert sep.count("|") == 10  # header, separator and rows: 9 columns each
    from doefab.tolerance.reporttext import _quantization

    without = dict(res, quantization=[r for r in res["quantization"] if r["levels"] != 16])  # its own count not judged
    assert "The change columns are empty: the design's own 16 levels are not among" in "\n".join(_quantization(without))


def test_a_metric_or_change_that_is_not_a_number_prints_a_dash():
    """A delivered value or change that is NaN (a network's output on a scene went bad) prints "—", never "nan";
    finite ones print as before."""
    from doefab.reconstruction.metrics import metric_text
    from doefab.tolerance.reporttext import delta_text

    assert metric_text("hdr", "psnr", float("nan")) == "—" and metric_text("hdr", "psnr", 29.891) == "29.89 dB"
    # an HDR RMSE is radiance relative to the plain capture's clipping level: printed with that scale, not bare
    from doefab.reconstruction.metrics import metric_label

    assert metric_text("hdr", "rmse", 0.1234) == "0.123 × clip" and metric_label("hdr", "rmse") == "RMSE (× clip)"
    assert metric_text("depth", "delta125", 0.8) == "0.800"  # a plain fraction stays bare
    got = delta_text("hdr", {"psnr": float("nan"), "psnr_highlight": -1.234}, {"psnr": 0.4, "psnr_highlight": 0.5})
    assert got == "PSNR —, highlight PSNR -1.23 ± 0.5 dB"
    assert delta_text("hdr", {"psnr": float("nan")}, names=False) == "—"


def test_studies_sharing_a_dask_scheduler_keep_their_own_parts_and_its_workers_run_this_code(tmp_path,
                                                                                               monkeypatch):
    """Two studies on one ``tcp://`` scheduler submit their parts under keys of their own (equal keys would be
    answered with the other study's parts); workers computing parts with other code are refused before any."""
    pytest.importorskip("dask.distributed")
    import dask.distributed as dd

    from doefab.tolerance.conditions import model_sources_sha256

    keys, digest = [], {"tcp://w1": model_sources_sha256()}

    class Done:
        def __init__(self, value):
            self.value = value

        def result(self):
            return self.value

    class FakeClient:
        def __init__(self, address):
            pass

        def run(self, fn, *args):
            return digest if fn is model_sources_sha256 else {}

        def submit(self, fn, *args, key, **kw):
            keys.append(key)
            return Done({"metric": 0.5})

        def close(self):
            pass

    monkeypatch.setattr(dd, "Client", FakeClient)
    monkeypatch.setattr(dd, "as_completed", lambda futs: list(futs))
    errs = {i: PartErrors() for i in range(3)}
    got = []
    for _ in range(2):
        montecarlo._run_dask("tcp://127.0.0.1:1", "d", 1, [0, 1, 2], errs, lambda i, r: got.append(i))
    assert got == [0, 1, 2, 0, 1, 2] and len(set(keys)) == 6  # no key of one study is the other's
    digest["tcp://w2"] = "0" * 64
    with pytest.raises(doefab.DoefabError, match="workers tcp://w2 run another version of doefab's part model"):
        montecarlo._run_dask("tcp://127.0.0.1:1", "d", 1, [0], errs, lambda i, r: None)
    assert len(keys) == 6  # refused before any part was submitted


def test_a_dask_scheduler_without_workers_is_said_before_the_parts_wait(monkeypatch, capsys):
    """A ``tcp://`` scheduler with no worker yet: the parts wait for one (a worker may join later), and the terminal
    says so and how to start one, instead of a progress bar that never moves; with a worker nothing is said."""
    pytest.importorskip("dask.distributed")
    import dask.distributed as dd

    from doefab.tolerance.conditions import model_sources_sha256

    workers = {}

    class FakeClient:
        def __init__(self, address):
            pass

        def run(self, fn, *args):
            return dict(workers) if fn is model_sources_sha256 else {}

        def submit(self, fn, *args, key, **kw):
            return key

        def close(self):
            pass

    monkeypatch.setattr(dd, "Client", FakeClient)
    monkeypatch.setattr(dd, "as_completed", lambda futs: [])  # what arrives later is not this test's
    errs = {0: PartErrors()}
    montecarlo._run_dask("tcp://10.1.2.3:8786", "d", 1, [0], errs, lambda i, r: None)
    err = capsys.readouterr().err
    assert "the scheduler tcp://10.1.2.3:8786 has no workers yet" in err
    assert "dask worker tcp://10.1.2.3:8786" in err
    workers["tcp://w1"] = model_sources_sha256()
    montecarlo._run_dask("tcp://10.1.2.3:8786", "d", 1, [0], errs, lambda i, r: None)
    assert capsys.readouterr().err == ""


def test_a_dask_worker_that_joins_after_the_check_with_other_code_is_refused_at_its_part(monkeypatch):
    """The check of a ``tcp://`` scheduler's workers runs at the study's start; a worker that joins later is checked
    where it computes a part (``_part_on_worker``: this process's part-model digest goes with each part), and its
    part is refused with the same error, never recorded; a worker with this code computes the part."""
    pytest.importorskip("dask.distributed")
    import dask.distributed as dd

    from doefab._devices import ENV
    from doefab.tolerance import study
    from doefab.tolerance.conditions import model_sources_sha256

    monkeypatch.delenv(ENV, raising=False)  # a worker sets its device there: restored after the test
    calls = []
    monkeypatch.setattr(study, "evaluate_part", lambda *a: calls.append(a) or {"metric": 0.5})
    here = model_sources_sha256()
    assert montecarlo._part_on_worker(here, "cpu", "d", 1, "{}", False, None) == {"metric": 0.5}
    assert calls == [("d", 1, "{}", False, None)]  # evaluate_part's own arguments, in its order
    late = montecarlo._part_on_worker("0" * 64, "cpu", "d", 1, "{}", False, None)
    assert late == {montecarlo.OTHER_CODE: "(a worker)"} and len(calls) == 1  # not computed with other code

    class Done:
        def __init__(self, value):
            self.value = value

        def result(self):
            return self.value

    class FakeClient:  # every worker at the start runs this code; the part of key 1 lands on a late one
        def __init__(self, address):
            pass

        def run(self, fn, *args):
            return {"tcp://w1": here} if fn is model_sources_sha256 else {}

        def submit(self, fn, *args, key, **kw):
            assert fn is montecarlo._part_on_worker and args[0] == here  # the digest goes with the part
            return Done({montecarlo.OTHER_CODE: "tcp://w9"} if key.endswith("-1") else fn(*args))

        def close(self):
            pass

    monkeypatch.setattr(dd, "Client", FakeClient)
    monkeypatch.setattr(dd, "as_completed", lambda futs: list(futs))
    got, errs = [], {i: PartErrors(seed=i) for i in range(3)}
    with pytest.raises(doefab.DoefabError, match="workers tcp://w9 run another version of doefab's part model"):
        montecarlo._run_dask("tcp://127.0.0.1:1", "d", 1, [0, 1, 2], errs, lambda i, r: got.append(i), False, "w")
    assert got == [0]  # the late worker's part is not recorded
    # each part reached evaluate_part with the arguments _run_dask forwards (parts 0 and 2 on workers of this code)
    assert calls[-2:] == [("d", 1, errs[i].to_json(), False, "w") for i in (0, 2)]


def test_a_resume_of_another_study_is_refused_before_its_steps_are_judged_or_replaced(design_dir, tmp_path):
    """run_study reads samples.jsonl's header first: a changed budget is refused with the finished grid study and
    tornado of the earlier study as they were."""
    from doefab.tolerance.report import STEPS, run_study

    budget = load_budget()
    run_study(design_dir, budget, tmp_path, samples=2, seed=1, grid=1, progress=False)
    steps = {p.name: p.read_bytes() for p in (tmp_path / STEPS).iterdir()}
    other = {**budget, "overlay": {**budget["overlay"], "shift_sigma_um": 1.0}}
    for g in (1, "auto"):
        with pytest.raises(doefab.DoefabError, match="written for another run.*budget_sha256"):
            run_study(design_dir, other, tmp_path, samples=2, seed=1, grid=g, progress=False)
    assert {p.name: p.read_bytes() for p in (tmp_path / STEPS).iterdir()} == steps


def test_a_last_row_that_lost_only_its_newline_is_kept(design_dir, tmp_path):
    budget = load_budget()
    full = montecarlo.monte_carlo(design_dir, budget, 3, tmp_path / "r", seed=1, progress=False)
    log = tmp_path / "r" / "samples.jsonl"
    log.write_text(log.read_text().rstrip("\n"))  # killed between a row and its newline
    again = montecarlo.monte_carlo(design_dir, budget, 3, tmp_path / "r", seed=1, progress=False)
    rows = [json.loads(line) for line in log.read_text().splitlines()]
    assert [r["index"] for r in rows[1:]] == [0, 1, 2] and [r["metric"] for r in again] == [r["metric"] for r in full]


def test_tolerance_force_removes_the_earlier_results_and_keeps_a_users_file(design_dir, tmp_path, monkeypatch):
    """--force starts afresh: an interrupted forced study leaves no tolerance.json or report of the earlier one
    (which would read as its result), while a file of the user's in the folder stays; a forced study refused
    before it starts (its design unreadable as a study) keeps the earlier one's."""
    import doefab.tolerance.montecarlo as mc
    from doefab.errors import DoefabError

    out = tmp_path / "t"
    argv = ["tolerance", "--design", str(design_dir), "--samples", "2", "--grid", "1", "--out", str(out)]
    assert main(argv) == 0
    done = {"tolerance.json", "report.md", "tornado.png", "samples.jsonl"}
    assert done <= {p.name for p in out.iterdir()}
    (out / "my_notes.png").write_bytes(b"mine")

    def refused(*a, **k):
        raise DoefabError("this design cannot be studied")

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(study, "judge_for", refused)
    assert main(argv + ["--force"]) == 2
    assert done <= {p.name for p in out.iterdir()}  # refused before any part: nothing of the earlier study lost
    monkeypatch.undo()
    monkeypatch.setattr(mc, "check_resumable", interrupted)  # interrupted once the fresh study has begun
    assert main(argv + ["--force"]) == 130
    left = {p.name for p in out.iterdir()}
    assert not left & {"tolerance.json", "report.md", "tornado.png", "samples.jsonl", "steps"}, left
    assert (out / "my_notes.png").read_bytes() == b"mine"


def test_tolerance_takes_default_for_the_shipped_budget_as_a_scene_does(design_dir, tmp_path):
    """``--budget default`` (any case) is the shipped budget, as ``tolerance.budget = "default"`` is in a scene;
    it was read as a file named default and refused."""
    out = tmp_path / "t"
    assert main(["tolerance", "--design", str(design_dir), "--samples", "2", "--grid", "1", "--budget", "Default",
                 "--out", str(out)]) == 0
    assert json.loads((out / "tolerance.json").read_text())["budget_file"].endswith("(default)")
