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


def test_calibration_restores_the_crosstalk_loss(design_dir):
    j = study._judge(str(design_dir), 1)
    nominal = j.score(j.nominal)
    bad = j.evaluate(PartErrors(crosstalk=(0.1, 0.1), calibrated=False))
    good = j.evaluate(PartErrors(crosstalk=(0.1, 0.1), calibrated=True))
    assert bad["l1_to_nominal"] > 0.01 and good == nominal


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
