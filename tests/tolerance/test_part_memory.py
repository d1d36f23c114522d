"""A judged part's memory (``tolerance.fields.part_bytes``): the estimate covers the peak a part's PSFs reach,
measured in a process of its own; a study whose parts do not fit is refused before any part is judged, naming the
grid that fits; the Monte Carlo starts no more worker processes than fit; doctor shows the row."""

import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from doefab.errors import DoefabError
from doefab.tolerance import fields
from doefab.tolerance.grid import GRIDS

REPO = Path(__file__).resolve().parents[2]

# a BANDS-band, 16-level streak design of N pixels on the twofold grid; the process's peak resident memory before and
# after one turned part's two halves
PROBE = """
import json, numpy as np, torch
import doefab
from doefab.design.design import Design
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

def peak():
    return next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmHWM"))

torch.set_num_threads(1)
doefab.keep_freed_memory()  # as every doefab command runs
n, bands = N, BANDS
cam = doefab.Camera(aperture_diameter=n * 5.4e-6, doe_pitch=5.4e-6, doe_pixels=n, sensor_pitch=5.4e-6,
                    sensor_distance=50e-3, focus_distance=5.0)
lv = np.random.default_rng(0).integers(0, 16, (n, n)).astype(np.uint8)
lv[:, n // 2:] = 15
d = Design(task="streak", task_params={"kernel_size": 31, "arm_px": 8}, camera=cam,
           wavelengths=tuple(np.linspace(450e-9, 650e-9, bands)), depths=(5.0,),
           height=doefab.levels_to_height(lv, cam), levels=lv,
           metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
judge = PSFJudge(d, 2)
before = peak()
with torch.no_grad():
    judge.psfs(PartErrors(mount_rotation=2e-3), halves=("coded", "uncoded"))
print(json.dumps({"before": before, "after": peak()}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
@pytest.mark.parametrize("n, bands", [(1024, 3), (640, 31)])
def test_the_estimate_covers_a_parts_measured_peak_without_overstating_it_much(n, bands):
    code = PROBE.replace("N, BANDS", f"{n}, {bands}")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True)
    m = json.loads(out.stdout.strip().splitlines()[-1])
    est = fields.part_bytes(n, 2, 4, bands)
    assert m["after"] <= est, m  # the whole process, torch and the judge included
    grown, per_cell = m["after"] - m["before"], est - fields.PROCESS_BYTES  # what the estimate gives the cells
    assert grown >= 0.5 * per_cell, (grown, per_cell)  # not far above it
    # 4.2 M cells: the part's own growth is within the cells' share alone (0.89 of 1.07 GB, freed memory kept)
    if bands == 3:
        assert grown <= per_cell, (grown, per_cell)


def test_part_bytes_grows_with_the_cells_the_pattern_areas_and_the_bands_built_at_once():
    one = fields.part_bytes(1000, 1, 4) - fields.PROCESS_BYTES
    assert fields.part_bytes(1000, 2, 4) - fields.PROCESS_BYTES == 4 * one  # (S·N)² cells
    assert fields.part_bytes(2000, 1, 4) - fields.PROCESS_BYTES == 4 * one
    assert fields.part_bytes(1000, 1, 5) > fields.part_bytes(1000, 1, 4) > fields.part_bytes(1000, 1, 1)
    assert fields.part_bytes(1000, 1, 4, 31) - fields.part_bytes(1000, 1, 4, 1) == 16 * 30 * 1000**2
    # above FIELD_BYTES the bands are built one at a time: their count no longer matters, a few at a time count
    assert fields.part_bytes(4000, 2, 4, 31) == fields.part_bytes(4000, 2, 4, 1) - 16 * 8000**2 + 240 * 8000**2
    assert fields.part_bytes(4000, 2, 4, 31) == fields.part_bytes(4000, 2, 4, 64)


def test_a_study_that_does_not_fit_is_refused_naming_a_grid_the_study_measured():
    size = (2000, 4, 3)
    have = fields.part_bytes(2000, 2, 4, 3) + 1  # the twofold grid fits, the fourfold does not
    fields.require_memory(size, 2, GRIDS, available=have)  # fits: nothing raised
    with pytest.raises(DoefabError) as e:
        bounds = {"1": 0.02, "2": 0.004, "4": 0.001}  # as the cached grid record holds them (JSON keys)
        fields.require_memory(size, 4, GRIDS, bounds=bounds, available=have)
    msg = str(e.value)
    assert "4× grid needs about 16.9 GB" in msg  # 8000² cells × (112 + 6·16 + 16·3) B + 0.5 GiB
    assert "tolerance.supersample = 2" in msg and "--grid 2" in msg
    assert "by 0.004" in msg  # what the coarser grid costs, from the grid study
    with pytest.raises(DoefabError, match="supersample = 4"):  # 8×: the next grid down the study measured is 4×
        fields.require_memory(size, 8, GRIDS, available=fields.part_bytes(2000, 7, 4, 3))
    with pytest.raises(DoefabError, match="2 parts at once .* fewer workers"):
        fields.require_memory(size, 2, GRIDS, parts=2, available=have)
    with pytest.raises(DoefabError, match="machine with 2 GB free") as e:
        fields.require_memory(size, 1, GRIDS, available=10**6)  # not even the design grid
    assert "supersample" not in str(e.value)


def test_a_scene_side_by_side_that_does_not_fit_its_share_is_told_to_run_fewer_at_once(monkeypatch):
    from doefab._memory import SHARE_ENV

    size = (2000, 4, 3)
    monkeypatch.setenv(SHARE_ENV, str(10**6))
    with pytest.raises(DoefabError, match=f"{SHARE_ENV} limits this process.*--jobs 1"):
        fields.require_memory(size, 1, GRIDS, available=10**6)


def test_a_study_is_refused_before_any_part_when_memory_is_short(design_dir, tmp_path, monkeypatch):
    import doefab._memory
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.report import run_study

    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: fields.part_bytes(100, 1, 4) + 1)
    with pytest.raises(DoefabError, match="supersample = 1"):
        run_study(design_dir, load_budget(None), tmp_path / "s", samples=2, grid=2, progress=False)
    # a tcp:// cluster judges the Monte Carlo elsewhere, but the tornado here: refused all the same (a listening
    # socket stands for the scheduler, which must answer before any work)
    with socket.create_server(("127.0.0.1", 0)) as server, pytest.raises(DoefabError, match="supersample = 1"):
        run_study(design_dir, load_budget(None), tmp_path / "t", samples=2, grid=2, progress=False,
                  scheduler=f"tcp://127.0.0.1:{server.getsockname()[1]}")
    with pytest.raises(DoefabError, match="2 parts at once"):  # two local Dask workers on the design grid
        run_study(design_dir, load_budget(None), tmp_path / "u", samples=2, grid=1, progress=False, scheduler="local:2")
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

    text = (REPO / "scenes" / "hdr.toml").read_text()
    assert "supersample = 1" in text
    free = tmp_path / "free.toml"  # the grid left to the grid study
    free.write_text(text.replace("supersample = 1", ""))

    def row(path):
        scene = load_scene(path)
        return scene, next(r for r in diagnose(scene, precision_check=False) if "judged part" in r["check"])
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 10**12)
    scene, fixed = row(REPO / "scenes" / "hdr.toml")
    n = resolve(scene).camera.doe_pixels
    bands = len(resolve(scene).settings["wavelengths_m"])
    assert fixed["ok"] and fixed["value"] == fields.part_bytes(n, 1, 4, bands) and "4×" not in fixed["check"]
    _, auto = row(free)
    assert auto["ok"] and auto["value"] == fields.part_bytes(n, 1, 4, bands)
    for g in (4, 8):  # what a finer grid would take
        assert f"{g}× {fields.part_bytes(n, g, 4, bands) / 1e9:.1f} GB" in auto["check"]
    pool = tmp_path / "pool.toml"  # three local workers judge three parts at once
    pool.write_text(text.replace("supersample = 1", "supersample = 1\nworkers = 3"))
    _, three = row(pool)
    assert three["value"] == 3 * fields.part_bytes(n, 1, 4, bands) and "3 judged parts" in three["check"]
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 2 * fields.part_bytes(n, 1, 4, bands))
    assert row(REPO / "scenes" / "hdr.toml")[1]["ok"] and not row(pool)[1]["ok"]
    assert "fewer tolerance workers" in row(pool)[1]["fix"]
    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 10**6)
    _, bad = row(REPO / "scenes" / "hdr.toml")
    assert not bad["ok"] and "more memory" in bad["fix"]
    # run refuses, before any stage, exactly what doctor fails
    from doefab.errors import DoefabError
    from doefab.pipeline.run import prepare_scene

    monkeypatch.setattr(doefab._memory, "available_bytes", lambda: 2 * fields.part_bytes(n, 1, 4, bands))
    prepare_scene(load_scene(REPO / "scenes" / "hdr.toml"), tmp_path / "run1")
    with pytest.raises(DoefabError, match=r"3 judged parts.* GB available: use a machine with more memory.*fewer "
                                          r"tolerance workers"):
        prepare_scene(load_scene(pool), tmp_path / "run3")
    assert not (tmp_path / "run3").exists()


def resolve(scene):
    from doefab.pipeline.stages import resolve

    return resolve(scene)


def test_the_room_under_a_containers_memory_limit_counts_its_page_cache_as_free(tmp_path, monkeypatch):
    import builtins

    from doefab._memory import _cgroup_rooms

    real_open = builtins.open
    monkeypatch.setattr(builtins, "open", lambda f, *a, **k: real_open(tmp_path / "cgroup" if str(f) ==
                                                                        "/proc/self/cgroup" else f, *a, **k))
    (tmp_path / "cgroup").write_text("0::/job/step\n")
    root = tmp_path / "fs"
    step, job = root / "job" / "step", root / "job"
    step.mkdir(parents=True)
    (step / "memory.max").write_text("max\n")  # no limit of its own
    (job / "memory.max").write_text("1000000\n")
    (job / "memory.current").write_text("600000\n")
    (job / "memory.stat").write_text("anon 400000\ninactive_file 100000\n")
    (root / "memory").mkdir()  # a cgroup v1 memory controller too
    (root / "memory" / "memory.limit_in_bytes").write_text("800000\n")
    (root / "memory" / "memory.usage_in_bytes").write_text("300000\n")
    (root / "memory" / "memory.stat").write_text("total_inactive_file 50000\n")
    assert _cgroup_rooms(root) == [1000000 - 500000, 800000 - 250000]
    (job / "memory.max").write_text("max\n")
    (root / "memory" / "memory.limit_in_bytes").write_text("9223372036854771712\n")  # v1's "no limit"
    assert _cgroup_rooms(root) == []
