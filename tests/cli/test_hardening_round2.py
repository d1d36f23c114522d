"""One test per row of the second hardening issue (issue 21), each replaying the row's exact case."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import doefab
from doefab.cli import main
from doefab.errors import DoefabError

REPO = Path(__file__).resolve().parents[2]


def _scene(tmp: Path, name: str = "X.toml", **lines) -> Path:
    """A copy of scenes/hdr.toml with whole lines replaced: ``stages='stages = ["holder"]'``."""
    text = (REPO / "scenes" / "hdr.toml").read_text()
    for key, line in lines.items():
        text, n = re.subn(rf"(?m)^{key} = .*$", line, text)
        assert n == 1, key
    (tmp / name).write_text(text)
    return tmp / name


def _holder_scene(tmp: Path) -> Path:
    return _scene(tmp, "S.toml", stages='stages = ["holder"]')


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


def _run(argv, capsys) -> tuple[int, str, str]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # parse-time errors
        rc = exc.code
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


# ---- row 1: only the ownership marker proves a folder is doefab's

def test_row01_a_users_run_json_is_not_a_signature(tmp_path, capsys):
    u = tmp_path / "u"
    (u / "holder").mkdir(parents=True)
    (u / "run.json").write_text('{"mine":1}\n')
    (u / "holder" / "my_part.scad").write_text("cad\n")
    scene = _holder_scene(tmp_path)
    before = _snapshot(tmp_path)
    rc, _, err = _run(["run", scene, "--out", u], capsys)
    assert rc == 2 and "ownership marker" in err
    assert _snapshot(tmp_path) == before


def test_row01_a_users_summary_json_is_not_a_demo_output(tmp_path, capsys):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "summary.json").write_text("{}\n")
    rc, _, err = _run(["demo", "--out", tmp_path / "d"], capsys)
    assert rc == 2 and "not a doefab demo output" in err
    assert [p.name for p in (tmp_path / "d").iterdir()] == ["summary.json"]


def test_row01_a_stage_folder_is_replaced_only_if_doefab_made_it(tmp_path, capsys):
    from doefab.io import mark_folder

    out = tmp_path / "run"
    out.mkdir()
    mark_folder(out, "run")  # doefab's run folder, holding a folder of the user's named like a stage
    (out / "holder").mkdir()
    (out / "holder" / "my_part.scad").write_text("cad\n")
    scene = _holder_scene(tmp_path)
    before = _snapshot(tmp_path)
    rc, _, err = _run(["run", scene, "--out", out], capsys)
    assert rc == 2 and "holder" in err and "ownership marker" in err
    assert _snapshot(tmp_path) == before


def test_row01_doefab_stage_folders_carry_their_marker_and_are_replaced(tmp_path, monkeypatch):
    from doefab.io import MARKER, read_marker
    from doefab.pipeline import stages
    from doefab.pipeline.run import foreign_stage_folders
    from doefab.pipeline.scene import load_scene

    calls = []

    def fake_holder(scene, res, out, quick):
        calls.append(sorted(p.name for p in out.iterdir()))
        (out / f"part{len(calls)}.stl").write_text("solid\n")
        return {"status": "ran", "why": "test"}

    monkeypatch.setitem(stages.STAGE_FUNCS, "holder", fake_holder)
    scene = load_scene(_holder_scene(tmp_path))
    for _ in range(2):
        stages.run_stage(scene, None, "holder", tmp_path / "run", {}, quick=True, force=True)
    # the second run started from an empty folder: the marker and the stage's "started" record only
    assert calls == [[MARKER, "stage.json"], [MARKER, "stage.json"]]
    assert sorted(p.name for p in (tmp_path / "run" / "holder").iterdir()) == [MARKER, "part2.stl", "stage.json"]
    assert read_marker(tmp_path / "run" / "holder") == {"kind": "run stage", "written_by": "doefab",
                                                         "stage": "holder"}
    assert foreign_stage_folders(scene, tmp_path / "run") == []


# ---- row 2: masks --verify re-derives every depth

def _half_ring_copy(tmp: Path) -> Path:
    dst = tmp / "COPY"
    shutil.copytree(REPO / "masks" / "half-ring", dst)
    return dst


def _edit_manifest(folder: Path, edit) -> None:
    man = json.loads((folder / "manifest.json").read_text())
    edit(man)
    (folder / "manifest.json").write_text(json.dumps(man, indent=2))


def test_row02_verify_names_every_inconsistent_depth_field(tmp_path, capsys):
    copy = _half_ring_copy(tmp_path)

    def edit(man):
        assert man["layers"][4]["etch_depth_nm"] == 597.942
        man["layers"][4]["etch_depth_nm"] = 1000
        man["level_step_nm"] *= 1.1

    _edit_manifest(copy, edit)
    rc, out, err = _run(["masks", "--verify", copy], capsys)
    assert rc == 3 and "verified" not in out
    assert "layers[4].etch_depth_nm = 1000 (expected 597.942" in err and "level_step_nm = 82.2" in err


def test_row02_rounding_passes_and_a_ten_percent_step_fails():
    from doefab.fabrication.manifest import depth_fields, depth_problems

    man = json.loads((REPO / "masks" / "half-ring" / "manifest.json").read_text())
    assert depth_problems(man) == []
    exact = depth_fields(doefab.FUSED_SILICA, man["design_wavelength_m"])
    rounded = dict(man, level_to_height_nm=[h + 0.0005 for h in exact["level_to_height_nm"]])
    assert depth_problems(rounded) == []  # float rounding of the written values passes
    step = dict(man, level_step_nm=man["level_step_nm"] * 1.1)
    assert [p.split(" =")[0] for p in depth_problems(step)] == ["level_step_nm"]
    table = dict(man, level_to_height_nm=[*man["level_to_height_nm"][:15], 1200.0])
    assert [p.split(" =")[0] for p in depth_problems(table)] == ["level_to_height_nm[15]"]
    assert "unknown material 'BK7'" in " ".join(depth_problems(dict(man, material={**man["material"], "name": "BK7"})))


def test_row02_a_consistently_edited_wavelength_differs_from_the_design(tmp_path, capsys):
    from doefab.fabrication.manifest import depth_fields

    copy = _half_ring_copy(tmp_path)

    def edit(man):  # every depth re-derived for 600 nm: self-consistent, but not the design's wavelength
        f = depth_fields(doefab.FUSED_SILICA, 600e-9)
        man.update(design_wavelength_m=600e-9, level_step_nm=f["level_step_nm"],
                   level_to_height_nm=f["level_to_height_nm"],
                   refractive_index_at_design_wavelength=f["refractive_index_at_design_wavelength"])
        for layer in man["layers"]:
            if layer["purpose"] == "etch":
                layer["etch_depth_nm"] = f["etch_depth_nm"][layer["bit"]]

    _edit_manifest(copy, edit)
    rc, _, err = _run(["masks", "--verify", copy, "--no-klayout"], capsys)
    assert rc == 3 and "differs from the design's 5.5e-07" in err


def test_row02_a_hand_edited_readme_fails(tmp_path, capsys):
    copy = _half_ring_copy(tmp_path)
    text = (copy / "README.txt").read_text()
    (copy / "README.txt").write_text(text.replace("etch depth 597.942 nm", "etch depth 1000 nm"))
    rc, _, err = _run(["masks", "--verify", copy, "--no-klayout"], capsys)
    assert rc == 3 and "README.txt differs" in err


# ---- row 3: shipped weights are never replaced by accident

def _digest(folder: Path, pattern: str) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.glob(pattern))}


def test_row03_train_writes_to_out_and_prints_the_path(tmp_path, capsys, monkeypatch):
    import doefab.reconstruction.train as train_mod
    from doefab.reconstruction.weights import WEIGHTS_DIR

    shipped = WEIGHTS_DIR
    before = _digest(shipped, "hdr_uncoded_only*")
    real = train_mod.train
    monkeypatch.setattr(train_mod, "train", lambda *a, **k: real(*a, val_images=1,
                                                                 **{**k, "max_steps": 1, "conditions": None}))
    rc, out, _ = _run(["train", "--task", "hdr", "--variant", "uncoded_only", "--minutes", "0.1", "--crop", "64",
                       "--clean", "--out", tmp_path / "tr"], capsys)
    assert rc == 0
    assert _digest(shipped, "hdr_uncoded_only*") == before
    written = (tmp_path / "tr" / "hdr_uncoded_only.pt").resolve()
    assert written.is_file() and f"wrote {written} and its .json" in out


def test_row03_the_shipped_folder_needs_the_explicit_flag(tmp_path, capsys):
    from doefab.reconstruction.weights import WEIGHTS_DIR, weights_target

    rc, _, err = _run(["train", "--task", "hdr", "--weights-dir", WEIGHTS_DIR, "--out", tmp_path / "tr"], capsys)
    assert rc == 2 and "--replace-shipped" in err and not (tmp_path / "tr").exists()
    assert weights_target(None, tmp_path, replace_shipped=True) == WEIGHTS_DIR
    with pytest.raises(DoefabError, match="committed design"):
        weights_target(None, tmp_path, replace_shipped=True, design=tmp_path)


# ---- rows 7 and 8: units and ranges at the API

def test_row07_fabricated_height_gives_the_unit_error(tiny_camera):
    levels = np.zeros((tiny_camera.doe_pixels,) * 2, np.uint8)
    with pytest.raises(DoefabError, match="550 nm is 5.5e-07 m"):
        doefab.fabricated_height(levels, tiny_camera, design_wavelength=550)
    with pytest.raises(DoefabError, match="550 nm is 5.5e-07 m"):
        doefab.Camera(design_wavelength=550)


def test_row08_reconstructor_refuses_captures_outside_0_1():
    rec = doefab.load_reconstructor("hdr")
    rng = np.random.default_rng(0)
    coded, uncoded = rng.random((3, 64, 64)).astype(np.float32), rng.random((3, 64, 64)).astype(np.float32)
    with pytest.raises(DoefabError, match=r"captures are in \[0, 1\].*divide by the white level"):
        rec(coded * 255, uncoded * 255)
    with pytest.raises(DoefabError, match="integer .uint8. image.*255 for 8 bits"):
        rec((coded * 255).astype(np.uint8), (uncoded * 255).astype(np.uint8))
    with pytest.raises(DoefabError, match="subtract the black level"):
        rec(coded - 0.5, uncoded)


# ---- row 9: the scheduler is checked when the flags are parsed

@pytest.mark.parametrize("scheduler", ["local:0", "local:abc", "tcp://nohost"])
def test_row09_scheduler_checked_at_parse_time(tmp_path, scheduler):
    """Run as its own process with a time limit: the case used to hang until killed."""
    p = subprocess.run([sys.executable, "-m", "doefab", "tolerance", "--design", str(REPO / "masks" / "grating"),
                        "--samples", "1", "--scheduler", scheduler, "--out", str(tmp_path / "t0")],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 2 and "--scheduler" in p.stderr and not (tmp_path / "t0").exists()


def test_row09_an_unreachable_scheduler_is_refused_before_any_work(tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rc, _, err = _run(["tolerance", "--design", REPO / "masks" / "grating", "--samples", "1", "--scheduler",
                       f"tcp://127.0.0.1:{port}", "--out", tmp_path / "t0"], capsys)
    assert rc == 2 and "no Dask scheduler answers" in err and not (tmp_path / "t0").exists()


# ---- rows 11 and 12: a design of another task is named as such, at once

def test_row11_train_names_the_task_design_mismatch(tmp_path, capsys):
    rc, _, err = _run(["train", "--task", "hdr", "--design", "masks/grating", "--weights-dir", tmp_path / "w",
                       "--minutes", "0.1", "--out", tmp_path / "trw"], capsys)
    assert rc == 2
    assert "masks/grating is a hyperspectral (grating) design; --task hdr needs a streak design" in err
    assert list(tmp_path.iterdir()) == []


def test_row12_evaluate_names_the_task_design_mismatch(tmp_path, capsys):
    rc, _, err = _run(["evaluate", "--task", "depth", "--design", "masks/grating", "--weights-dir", "doefab/weights",
                       "--images", "1", "--size", "64", "--out", tmp_path / "ev"], capsys)
    assert rc == 2 and "--task depth needs a half-ring design" in err and "doefab train" not in err


def test_row12_the_loader_never_suggests_overwriting_the_shipped_weights(tmp_path):
    from doefab.reconstruction.loader import _retrain

    hint = _retrain("depth", "proposed", None, tmp_path / "cand")
    assert "--weights-dir NEW_FOLDER" in hint and "--replace-shipped" not in hint
    assert _retrain("depth", "proposed", tmp_path / "w", None).endswith(f"--weights-dir {tmp_path / 'w'}")


# ---- row 13: the holder's stated bounds come first

@pytest.mark.parametrize("setting, needle", [("clearance_mm=10", "clearance_mm 10 is outside 0.05–1 mm"),
                                             ("thread_diameter_mm=1e9", "thread_diameter_mm 1e+09 is outside 20–150 mm")])
def test_row13_holder_names_the_parameter_and_its_bound(tmp_path, capsys, setting, needle):
    rc, _, err = _run(["holder", "--out", tmp_path / "h1", "--set", setting], capsys)
    assert rc == 2 and needle in err and "washers" not in err and "flange" not in err


# ---- rows 14–16: the run command

@pytest.mark.parametrize("edit", [{"depths_m": "depths_m = [5000.0]"}, {"preset": 'preset = "depth"'},
                                  {"stages": 'stages = ["tolerance", "report"]'}])
def test_row14_every_scene_check_before_the_folder_is_created(tmp_path, capsys, edit):
    rc, _, err = _run(["run", _scene(tmp_path, **edit), "--out", tmp_path / "o"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_row15_no_report_stage_says_no_report_was_written(tmp_path, capsys):
    """A scene without the report stage says so (an empty stage list is refused: it would run nothing)."""
    rc, out, _ = _run(["run", _scene(tmp_path, stages='stages = ["holder"]'), "--out", tmp_path / "o", "--quick"],
                      capsys)
    assert rc == 0 and "no report written" in out and "report.html" not in out
    assert not (tmp_path / "o" / "report.html").exists()
    rc, _, err = _run(["run", _scene(tmp_path, stages="stages = []"), "--out", tmp_path / "p"], capsys)
    assert rc == 2 and "stages" in err and not (tmp_path / "p").exists()


def test_row16_empty_out_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, _, err = _run(["run", _holder_scene(tmp_path), "--out", ""], capsys)
    assert rc == 2 and "--out is empty" in err and sorted(p.name for p in tmp_path.iterdir()) == ["S.toml"]


# ---- row 17: a long redesign is announced


def test_row17_a_redesign_says_why_and_roughly_how_long(tmp_path, capsys, monkeypatch):
    def stop(*a, **k):
        raise DoefabError("stopped by the test")

    monkeypatch.setattr(doefab, "optimize", stop)
    scene = _scene(tmp_path, kernel_px="kernel_px = 96", stages='stages = ["design"]')
    rc, out, err = _run(["run", scene, "--out", tmp_path / "o"], capsys)
    assert rc == 2 and "stopped by the test" in err
    line = [ln for ln in out.splitlines() if "is not reused" in ln]
    assert len(line) == 1 and "kernel_px 96 (committed 95)" in line[0]
    assert re.search(r"roughly \d+\.\d min", line[0]) and "checkpoint ~123 MB" in line[0]
    assert not (tmp_path / "o").exists()  # a failed run removes what it created


# ---- row 18: messages

def test_row18_a_folder_is_named_as_a_folder(tmp_path, capsys):
    (tmp_path / "somedir.toml").mkdir()
    rc, _, err = _run(["doctor", tmp_path / "somedir.toml"], capsys)
    assert rc == 2 and "is a folder" in err and "not found" not in err


def test_row18_wavelengths_in_metres_get_one_message_with_the_hint(tmp_path):
    from doefab.pipeline.scene import load_scene

    p = _scene(tmp_path, wavelengths_nm="wavelengths_nm = [6.56e-07, 5.89e-07, 4.86e-07]")
    with pytest.raises(DoefabError) as exc:
        load_scene(p)
    msg = str(exc.value)
    assert "1 problem(s)" in msg and msg.count("optics.wavelengths_nm") == 1 and "write 656" in msg


# ---- row 19: SIGTERM is handled like Ctrl-C

def test_row19_sigterm_cleans_up_like_ctrl_c(tmp_path):
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "doefab", "run", str(_holder_scene(tmp_path)), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    for line in proc.stdout:
        if "[doefab run] holder …" in line:
            break
    assert out.is_dir()  # the run is under way
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 143
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "terminated (SIGTERM)" in lines[0] and "nothing was kept" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["S.toml"]


# ---- row 20: the report

def test_row20_report_text_renders_and_says_what_is_a_benchmark(tmp_path):
    from doefab.pipeline.report import BENCHMARK, write_report
    from doefab.pipeline.scene import load_scene

    scene = load_scene(REPO / "scenes" / "hyperspectral.toml")
    from types import SimpleNamespace

    res = SimpleNamespace(settings={"design_task": "grating", "wavelengths_m": [5e-7] * 31, "depths_m": [5.0],
                                    "kernel_px": 191})  # a report of stages without a resolved scene
    write_report(tmp_path, scene, {"reconstruction": {"status": "reused", "weights": "shipped", "rows": {}}}, res)
    page = (tmp_path / "report.html").read_text()
    assert "`" not in page and f"<code>{scene.path}</code>" in page
    assert page.count(BENCHMARK) >= 3  # the PSF and design benchmark captions, and the section's note
    assert "not in this run" in page  # the shipped weights' training curves


def test_row20_design_psf_panels_are_drawn_on_a_log_scale(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import doefab.plotting
    from doefab.plotting import design_psf_figure

    seen = {}
    monkeypatch.setattr(doefab.plotting, "plot_psf_grid", lambda path, panels, pitch, **kw: seen.update(kw))
    d = SimpleNamespace(wavelengths=[5e-7, 6e-7], depths=[5.0], camera=SimpleNamespace(sensor_pitch=5.4e-6),
                        task="grating", n_levels=16)
    psf = np.zeros((1, 2, 15, 15))
    psf[0, :, 7, 7] = 1.0
    design_psf_figure(tmp_path / "f.png", d, psf, psf)
    assert seen["log"] is True and "log scale" in seen["suptitle"]


def test_doctor_out_replaces_only_its_own_report(tmp_path, capsys):
    """``doctor --out F`` writes F; a rerun replaces its own report; a file of the user's is never replaced."""
    f = tmp_path / "d.json"
    for _ in range(2):
        rc, _, _ = _run(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--out", f], capsys)
        assert rc == 0 and json.loads(f.read_text())["written_by"] == "doefab doctor"
    mine = tmp_path / "notes.txt"
    mine.write_text("my notes")
    rc, _, err = _run(["doctor", REPO / "scenes" / "hdr.toml", "--no-precision", "--out", mine], capsys)
    assert rc == 2 and "never replaces" in err and mine.read_text() == "my notes"


def test_train_never_replaces_a_users_file_in_weights_dir(tmp_path):
    from doefab.reconstruction.weights import weights_target

    w = tmp_path / "w"
    w.mkdir()
    (w / "hdr_proposed.json").write_text('{"mine": 1}')
    with pytest.raises(DoefabError, match="not written by doefab"):
        weights_target(w, tmp_path, task="hdr", variant="proposed")
    assert weights_target(w, tmp_path, task="hdr", variant="coded_only") == w  # other names are free
    (w / "hdr_proposed.json").write_text(json.dumps({"format": "doefab weights 1", "task": "hdr",
                                                     "variant": "proposed"}))
    assert weights_target(w, tmp_path, task="hdr", variant="proposed") == w  # doefab's own: replaced


def test_write_holder_never_writes_into_a_users_folder(tmp_path):
    from holder_cad.build import write_holder
    from holder_cad.params import HolderParams

    (tmp_path / "holder.stl").write_text("the user's own part")
    with pytest.raises(DoefabError, match="no doefab ownership marker"):
        write_holder(HolderParams(), tmp_path, step=False, renders=False)
    assert (tmp_path / "holder.stl").read_text() == "the user's own part"
    from doefab.io import mark_folder

    masks = tmp_path / "maskset"  # doefab's, but a mask set: no holder files go there
    masks.mkdir()
    mark_folder(masks, "masks")
    (masks / "manifest.json").write_text("{}")
    with pytest.raises(DoefabError, match="a doefab masks output"):
        write_holder(HolderParams(), masks, step=False, renders=False)
    assert sorted(p.name for p in masks.iterdir()) == [".doefab-output.json", "manifest.json"]
