"""Tolerance studies on a small design: crosstalk calibration, reproducible Monte Carlo on every backend,
resume, summary statistics, and the command."""

import json

import numpy as np
import pytest

import doefab
from doefab.cli import main
from doefab.design.design import Design
from doefab.tolerance import study
from doefab.tolerance.errors import PartErrors, load_budget


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory):
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


def test_a_noisy_calibration_leaves_its_own_error_and_no_more(design_dir):
    """Uncalibrated crosstalk costs; calibrated, the coded view is what the 2 × 2 algebra of Eq. 29 predicts for
    the estimated ratios (here written with numpy's inverse): the nominal view plus the calibration's error
    times the two halves — which vanishes as the calibration gets exact."""
    from doefab.tolerance.errors import crosstalk_ratios

    j = study._judge(str(design_dir), 1)
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
        gaps.append(abs(a_hat - a) + abs(b_hat - b))
        bound = abs(k[1, 0]) * float(plain.abs().sum()) + abs(k[1, 1] - 1) * float(coded.abs().sum())
        assert float((got - coded).abs().sum()) <= bound * (1 + 1e-9)
    assert gaps[0] > gaps[2] > 0  # more rows, a better estimate


def test_same_seed_same_numbers_in_process_pool_and_dask(design_dir, tmp_path):
    budget = load_budget()
    a = study.monte_carlo(design_dir, budget, 4, tmp_path / "a", seed=7, progress=False)
    b = study.monte_carlo(design_dir, budget, 4, tmp_path / "b", seed=7, workers=2, progress=False)
    pytest.importorskip("dask.distributed")
    c = study.monte_carlo(design_dir, budget, 4, tmp_path / "c", seed=7, scheduler="local:2", progress=False)
    key = lambda rows: [(r["index"], r["metric"], r["worst"], r["l1_to_nominal"], r["errors"]) for r in rows]  # noqa: E731
    assert key(a) == key(b) == key(c)
    d = study.monte_carlo(design_dir, budget, 4, tmp_path / "d", seed=8, progress=False)
    assert key(d) != key(a)


def test_interrupted_study_resumes(design_dir, tmp_path):
    budget = load_budget()
    full = study.monte_carlo(design_dir, budget, 4, tmp_path / "full", seed=1, progress=False)
    part = tmp_path / "part"
    study.monte_carlo(design_dir, budget, 4, part, seed=1, progress=False)
    lines = (part / "samples.jsonl").read_text().splitlines()
    (part / "samples.jsonl").write_text("\n".join(lines[:2]) + "\n" + lines[2][:20])  # killed mid-write
    again = study.monte_carlo(design_dir, budget, 4, part, seed=1, progress=False)
    assert [r["metric"] for r in again] == [r["metric"] for r in full]


def test_summary_statistics():
    rows = [{"metric": m, "worst": m, "l1_to_nominal": 0.0} for m in (0.4, 0.6, 0.6, 0.8)]
    s = study.summarize(rows, 0.5)
    assert s["metric"]["mean"] == pytest.approx(0.6)
    half = 1.96 * np.std([0.4, 0.6, 0.6, 0.8], ddof=1) / 2
    assert s["metric"]["ci95"] == pytest.approx([0.6 - half, 0.6 + half])
    assert s["yield"]["value"] == 0.75 and 0 < s["yield"]["ci95"][0] < 0.75 < s["yield"]["ci95"][1] <= 1


def test_command_writes_json_report_and_plots(design_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["tolerance", "--design", str(design_dir), "--samples", "3", "--sweep", "--levels",
                 "--out", str(out)]) == 0
    res = json.loads((out / "tolerance.json").read_text())
    assert len(res["samples"]) == 3 and "yield" in res["summary"] and res["tornado"]
    assert [r["levels"] for r in res["quantization"]] == ["continuous", 16, 8, 4, 2]
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
    gaps = [sample_errors(budget, np.random.default_rng(i)).axial_gap for i in range(200)]
    assert np.mean(gaps) == pytest.approx(1.6e-3, abs=3e-5) and 0.05e-3 < np.std(gaps) < 0.15e-3
