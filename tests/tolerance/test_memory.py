"""A judged part's memory (``tolerance.fields.part_bytes``): the estimate covers the peak a part's PSFs reach,
measured in a process of its own; a study whose parts do not fit is refused before any part is judged, naming the
grid that fits; the Monte Carlo starts no more worker processes than fit; doctor shows the row."""

import json
import subprocess
import sys

import pytest

from doefab.errors import DoefabError
from doefab.tolerance import fields

# a 1024-pixel, 16-level streak design on the twofold grid (4.2 M cells); the process's peak resident memory before
# and after one turned part's two halves
PROBE = """
import json, numpy as np, torch
import doefab
from doefab.design.design import Design
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

def peak():
    return next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmHWM"))

torch.set_num_threads(1)
n = 1024
cam = doefab.Camera(aperture_diameter=n * 5.4e-6, doe_pitch=5.4e-6, doe_pixels=n, sensor_pitch=5.4e-6,
                    sensor_distance=50e-3, focus_distance=5.0)
lv = np.random.default_rng(0).integers(0, 16, (n, n)).astype(np.uint8)
lv[:, n // 2:] = 15
d = Design(task="streak", task_params={"kernel_size": 31, "arm_px": 8}, camera=cam,
           wavelengths=(486e-9, 589e-9, 656e-9), depths=(5.0,), height=doefab.levels_to_height(lv, cam), levels=lv,
           metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
judge = PSFJudge(d, 2)
before = peak()
with torch.no_grad():
    judge.psfs(PartErrors(mount_rotation=2e-3), halves=("coded", "uncoded"))
print(json.dumps({"before": before, "after": peak()}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_the_estimate_covers_a_parts_measured_peak_without_overstating_it_much():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=600, check=True)
    m = json.loads(out.stdout.strip().splitlines()[-1])
    assert m["after"] <= fields.part_bytes(1024, 2, 4), m  # the whole process, torch and the judge included
    per_cell = fields.part_bytes(1024, 2, 4) - fields.PROCESS_BYTES  # what the estimate gives the part's cells
    assert m["after"] - m["before"] >= 0.5 * per_cell, m  # an estimate, not a ceiling far above it


def test_part_bytes_grows_with_the_cells_and_the_pattern_areas():
    one = fields.part_bytes(1000, 1, 4) - fields.PROCESS_BYTES
    assert fields.part_bytes(1000, 2, 4) - fields.PROCESS_BYTES == 4 * one  # (S·N)² cells
    assert fields.part_bytes(2000, 1, 4) - fields.PROCESS_BYTES == 4 * one
    assert fields.part_bytes(1000, 1, 5) > fields.part_bytes(1000, 1, 4) > fields.part_bytes(1000, 1, 1)


def test_a_study_that_does_not_fit_is_refused_naming_the_grid_that_does():
    have = fields.part_bytes(2000, 2, 4) + 1  # the twofold grid fits, the fourfold does not
    fields.require_memory(2000, 2, 4, available=have)  # fits: nothing raised
    with pytest.raises(DoefabError) as e:
        fields.require_memory(2000, 4, 4, bounds={1: 0.02, 2: 0.004, 4: 0.001}, available=have)
    msg = str(e.value)
    assert "4× grid needs about 13.8 GB" in msg and "tolerance.supersample = 2" in msg and "--grid 2" in msg
    assert "by 0.004" in msg  # what the coarser grid costs, from the grid study
    with pytest.raises(DoefabError, match="machine with 2 GB free") as e:
        fields.require_memory(2000, 1, 4, available=10**6)  # not even the design grid
    assert "supersample" not in str(e.value)


def test_a_study_is_refused_before_any_part_when_memory_is_short(design_dir, tmp_path, monkeypatch):
    import doefab._memory
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.report import run_study

    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: fields.part_bytes(100, 1, 4) + 1)
    with pytest.raises(DoefabError, match="supersample = 1"):
        run_study(design_dir, load_budget(None), tmp_path / "s", samples=2, grid=2, progress=False)
    assert not (tmp_path / "s" / "samples.jsonl").exists()  # refused before the Monte Carlo
    assert not (tmp_path / "s" / "steps" / "tornado.json").exists()  # and before the tornado


def test_the_monte_carlo_starts_only_the_workers_that_fit(design_dir, tmp_path, monkeypatch):
    import concurrent.futures

    import doefab._memory
    from doefab.tolerance import montecarlo
    from doefab.tolerance.errors import load_budget

    class Started(Exception):
        pass

    def pool(*a, **k):
        raise Started(a)

    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", pool)
    monkeypatch.setattr(montecarlo.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    budget = load_budget(None)
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 2 * fields.part_bytes(100, 1, 4))
    with pytest.raises(Started):  # two cores, two parts' memory: a pool of two
        montecarlo.monte_carlo(design_dir, budget, 8, tmp_path / "a", progress=False)
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: fields.part_bytes(100, 1, 4) + 1)
    rows = montecarlo.monte_carlo(design_dir, budget, 8, tmp_path / "b", progress=False)  # one part's: in process
    assert len(rows) == 8


def test_doctor_shows_a_parts_memory_and_fails_where_it_does_not_fit(tmp_path, monkeypatch):
    import doefab._memory
    from doefab.pipeline.doctor import diagnose
    from doefab.pipeline.scene import load_scene

    text = open("scenes/hdr.toml").read()
    assert "supersample = 1" in text
    free = tmp_path / "free.toml"  # the grid left to the grid study
    free.write_text(text.replace("supersample = 1", ""))

    def row(path):
        scene = load_scene(path)
        return scene, next(r for r in diagnose(scene, precision_check=False) if "judged part's memory" in r["check"])
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 10**12)
    scene, fixed = row("scenes/hdr.toml")
    n = resolve(scene).camera.doe_pixels
    assert fixed["ok"] and fixed["value"] == fields.part_bytes(n, 1, 4) and "4×" not in fixed["check"]
    _, auto = row(free)
    assert auto["ok"] and auto["value"] == fields.part_bytes(n, 1, 4)
    assert f"4× {fields.part_bytes(n, 4, 4) / 1e9:.1f} GB" in auto["check"]  # what a finer grid would take
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 10**6)
    _, bad = row("scenes/hdr.toml")
    assert not bad["ok"] and "more memory" in bad["fix"]


def resolve(scene):
    from doefab.pipeline.stages import resolve

    return resolve(scene)
