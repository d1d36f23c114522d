"""``doefab run``: only the ownership marker proves a folder is doefab's, every scene check comes before the
output folder is created, a redesign is announced, messages name the key, SIGTERM cleans up like Ctrl-C."""

import signal
import subprocess
import sys

import pytest

import doefab
from doefab.errors import DoefabError

from cli_helpers import holder_scene, run_cli, scene_copy, snapshot


def test_a_users_run_json_is_not_a_signature(tmp_path, capsys):
    u = tmp_path / "u"
    (u / "holder").mkdir(parents=True)
    (u / "run.json").write_text('{"mine":1}\n')
    (u / "holder" / "my_part.scad").write_text("cad\n")
    scene = holder_scene(tmp_path)
    before = snapshot(tmp_path)
    rc, _, err = run_cli(["run", scene, "--out", u], capsys)
    assert rc == 2 and "ownership marker" in err
    assert snapshot(tmp_path) == before


def test_a_stage_folder_is_replaced_only_if_doefab_made_it(tmp_path, capsys):
    from doefab.io import mark_folder

    out = tmp_path / "run"
    out.mkdir()
    mark_folder(out, "run")  # doefab's run folder, holding a folder of the user's named like a stage
    (out / "holder").mkdir()
    (out / "holder" / "my_part.scad").write_text("cad\n")
    scene = holder_scene(tmp_path)
    before = snapshot(tmp_path)
    rc, _, err = run_cli(["run", scene, "--out", out], capsys)
    assert rc == 2 and "holder" in err and "ownership marker" in err
    assert snapshot(tmp_path) == before


def test_doefab_stage_folders_carry_their_marker_and_are_replaced(tmp_path, monkeypatch):
    from doefab.io import MARKER, read_marker
    from doefab.pipeline import stagerun as stages
    from doefab.pipeline.run import foreign_stage_folders
    from doefab.pipeline.scene import load_scene

    calls = []

    def fake_holder(scene, res, out, quick):
        calls.append(sorted(p.name for p in out.iterdir()))
        (out / f"part{len(calls)}.stl").write_text("solid\n")
        return {"status": "ran", "why": "test"}

    monkeypatch.setitem(stages.STAGE_FUNCS, "holder", fake_holder)
    scene = load_scene(holder_scene(tmp_path))
    for _ in range(2):
        stages.run_stage(scene, None, "holder", tmp_path / "run", {}, quick=True, force=True)
    # the second run started from an empty folder: the marker and the stage's "started" record only
    assert calls == [[MARKER, "stage.json"], [MARKER, "stage.json"]]
    assert sorted(p.name for p in (tmp_path / "run" / "holder").iterdir()) == [MARKER, "part2.stl", "stage.json"]
    assert read_marker(tmp_path / "run" / "holder") == {"kind": "run stage", "written_by": "doefab",
                                                         "stage": "holder"}
    assert foreign_stage_folders(scene, tmp_path / "run") == []


@pytest.mark.parametrize("edit", [{"depths_m": "depths_m = [5000.0]"}, {"preset": 'preset = "depth"'},
                                  {"stages": 'stages = ["tolerance", "report"]'}])
def test_every_scene_check_before_the_folder_is_created(tmp_path, capsys, edit):
    rc, _, err = run_cli(["run", scene_copy(tmp_path, **edit), "--out", tmp_path / "o"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_no_report_stage_says_no_report_was_written(tmp_path, capsys):
    """A scene without the report stage says so (an empty stage list is refused: it would run nothing)."""
    rc, out, _ = run_cli(["run", scene_copy(tmp_path, stages='stages = ["holder"]'), "--out", tmp_path / "o", "--quick"],
                      capsys)
    assert rc == 0 and "no report written" in out and "report.html" not in out
    assert not (tmp_path / "o" / "report.html").exists()
    rc, _, err = run_cli(["run", scene_copy(tmp_path, stages="stages = []"), "--out", tmp_path / "p"], capsys)
    assert rc == 2 and "stages" in err and not (tmp_path / "p").exists()


def test_empty_out_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, _, err = run_cli(["run", holder_scene(tmp_path), "--out", ""], capsys)
    assert rc == 2 and "--out is empty" in err and sorted(p.name for p in tmp_path.iterdir()) == ["S.toml"]


def test_a_redesign_says_why_what_it_runs_and_where_its_time_is_measured(tmp_path, capsys, monkeypatch):
    def stop(*a, **k):
        raise DoefabError("stopped by the test")

    monkeypatch.setattr(doefab, "optimize", stop)
    scene = scene_copy(tmp_path, kernel_px="kernel_px = 96", stages='stages = ["design"]')
    rc, out, err = run_cli(["run", scene, "--out", tmp_path / "o"], capsys)
    assert rc == 2 and "stopped by the test" in err
    line = [ln for ln in out.splitlines() if "is not reused" in ln]
    assert len(line) == 1 and "kernel_px 96 (committed 95)" in line[0]
    assert "(60 adam iterations on a 3200² grid; doefab doctor measures its run time" in line[0]  # hdr.toml's
    assert "checkpoint ~123 MB" in line[0] and " min" not in line[0]  # no time scaled from another run's record
    assert not (tmp_path / "o").exists()  # a failed run removes what it created


def test_wavelengths_in_metres_get_one_message_with_the_hint(tmp_path):
    from doefab.pipeline.scene import load_scene

    p = scene_copy(tmp_path, wavelengths_nm="wavelengths_nm = [6.56e-07, 5.89e-07, 4.86e-07]")
    with pytest.raises(DoefabError) as exc:
        load_scene(p)
    msg = str(exc.value)
    assert "1 problem" in msg and msg.count("optics.wavelengths_nm") == 1 and "write 656" in msg


def test_sigterm_cleans_up_like_ctrl_c(tmp_path):
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "doefab", "run", str(holder_scene(tmp_path)), "--out", str(out)],
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
