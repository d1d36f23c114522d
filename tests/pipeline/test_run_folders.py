"""An output folder belongs to one run at a time, and a rerun keeps what doefab did not write: a second run on a
folder in use is refused (the lock ends with its holder), scenes that would share an output folder are refused
when the scenes are checked, and ``--force STAGE`` keeps a user's file in the stage folder."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from doefab.cli import main
from doefab.errors import DoefabError
from doefab.io import folder_lock
from doefab.pipeline.run import run_scene
from doefab.pipeline.scene import load_scene

REPO = Path(__file__).resolve().parents[2]


def _holder_scene(folder: Path, name: str = "x") -> Path:
    text = (REPO / "scenes" / "hdr.toml").read_text()
    stages = next(ln for ln in text.splitlines() if ln.startswith("stages = "))
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / f"{name}.toml"
    p.write_text(text.replace(stages, 'stages = ["holder"]'))
    return p


def test_a_folder_in_use_is_refused_and_released(tmp_path):
    scene = load_scene(_holder_scene(tmp_path))
    out = tmp_path / "out"
    out.mkdir()
    with folder_lock(out, "doefab run other.toml"):
        with pytest.raises(DoefabError, match=r"in use by doefab run other.toml \(process \d+"):
            run_scene(scene, out, quick=True, progress=False)
        assert not (out / "holder").exists()  # refused before any stage
    assert run_scene(scene, out, quick=True, progress=False)["stages"]["holder"]["status"] == "ran"


def test_the_lock_is_held_by_another_process_and_ends_with_it(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    code = textwrap.dedent(f"""
        import sys, time
        from doefab.io import folder_lock
        with folder_lock({str(out)!r}, "doefab run held.toml"):
            print("held", flush=True)
            sys.stdin.readline()
    """)
    child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "held"
        with pytest.raises(DoefabError, match=f"process {child.pid}"):
            with folder_lock(out):
                pass
    finally:
        child.kill()
        child.wait()
    with folder_lock(out):  # a killed holder leaves no stale lock
        pass


def test_scenes_that_share_an_output_folder_are_refused_before_any_work(tmp_path, monkeypatch, capsys):
    _holder_scene(tmp_path / "a")
    _holder_scene(tmp_path / "b")
    monkeypatch.chdir(tmp_path)
    assert main(["run", "a/x.toml", "b/x.toml", "--quick"]) == 2
    err = capsys.readouterr().err
    assert "a/x.toml, b/x.toml would all write out/run/x" in err and "--out" in err
    assert not (tmp_path / "out").exists()


def test_force_keeps_a_file_doefab_did_not_write(tmp_path):
    scene = load_scene(_holder_scene(tmp_path))
    out = tmp_path / "out"
    run_scene(scene, out, quick=True, progress=False)
    mine = out / "holder" / "my_measurements.txt"
    mine.write_text("flange 57.02 mm\n")
    (out / "holder" / "my_notes").mkdir()
    (out / "holder" / "my_notes" / "a.txt").write_text("a")
    run_scene(scene, out, force=("holder",), quick=True, progress=False)
    assert mine.read_text() == "flange 57.02 mm\n" and (out / "holder" / "my_notes" / "a.txt").read_text() == "a"
    rec = json.loads((out / "holder" / "stage.json").read_text())
    assert rec["complete"] and "my_measurements.txt" not in rec["files"] and "holder.stl" in rec["files"]

    # doefab's own files are still replaced: one that is gone from a rerun's output does not linger
    (out / "holder" / "holder.stl").write_text("stale")
    run_scene(scene, out, force=("holder",), quick=True, progress=False)
    assert (out / "holder" / "holder.stl").read_bytes()[:5] != b"stale" and mine.is_file()


def test_the_holder_stage_is_rebuilt_when_the_holder_code_changes(tmp_path, monkeypatch):
    """A holder built by another version of holder_cad (another flange rule, say) is not reused: the holder
    stage's hash covers holder_cad's source. The same source elsewhere gives the same hash."""
    import shutil

    import holder_cad
    from doefab.pipeline.stagerun import stage_hash

    scene = load_scene(_holder_scene(tmp_path))
    before = stage_hash(scene, "holder", {}, True)
    copy = tmp_path / "src" / "holder_cad"
    shutil.copytree(Path(holder_cad.__file__).parent, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(holder_cad, "__file__", str(copy / "__init__.py"))
    assert stage_hash(scene, "holder", {}, True) == before
    with open(copy / "params.py", "a") as fh:
        fh.write("\n# another flange rule\n")
    assert stage_hash(scene, "holder", {}, True) != before
    assert stage_hash(scene, "design", {}, True) == stage_hash(scene, "design", {}, True)


def test_a_users_file_inside_a_subfolder_doefab_writes_is_kept(tmp_path, monkeypatch):
    """A stage that writes a subfolder (the masks stage's design/, say): on a rerun its own files there are
    replaced, a file of the user's beside them is kept, and a subfolder left empty is removed."""
    import doefab.pipeline.stagerun as stages

    def fake_masks(scene, res, out, quick):
        (out / "design").mkdir(exist_ok=True)
        (out / "design" / "levels.npy").write_bytes(b"new")
        if not (out / "old_only").exists() and not getattr(fake_masks, "second", False):
            (out / "old_only").mkdir()
            (out / "old_only" / "x.bin").write_bytes(b"x")
        return {"status": "ran"}

    monkeypatch.setitem(stages.STAGE_FUNCS, "masks", fake_masks)
    scene = load_scene(_holder_scene(tmp_path))
    root = tmp_path / "out"
    stages.run_stage(scene, None, "masks", root, {}, True, force=False)
    rec = json.loads((root / "masks" / "stage.json").read_text())
    assert {"design/levels.npy", "old_only/x.bin"} <= set(rec["files"])
    note = root / "masks" / "design" / "my_note.txt"
    note.write_text("mine")
    fake_masks.second = True
    stages.run_stage(scene, None, "masks", root, {}, True, force=True)
    assert note.read_text() == "mine" and (root / "masks" / "design" / "levels.npy").read_bytes() == b"new"
    assert not (root / "masks" / "old_only").exists()  # doefab's own folder, emptied by the rerun, is gone
    rec = json.loads((root / "masks" / "stage.json").read_text())
    assert "design/my_note.txt" not in rec["files"] and "design/levels.npy" in rec["files"]


def test_an_interrupted_rerun_leaves_no_summary_of_the_earlier_run(tmp_path, monkeypatch):
    """run.json and the top-level report are written at a run's end: a rerun interrupted in a stage leaves none of
    the earlier run's (which would call the stage done, with the old numbers)."""
    from doefab.pipeline import stagerun

    path = _holder_scene(tmp_path)
    path.write_text(path.read_text().replace('stages = ["holder"]', 'stages = ["holder", "report"]'))
    scene = load_scene(path)
    out = tmp_path / "out"
    run_scene(scene, out, quick=True, progress=False)
    assert (out / "run.json").is_file() and (out / "report.md").is_file()

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setitem(stagerun.STAGE_FUNCS, "holder", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_scene(scene, out, force=("holder",), quick=True, progress=False)
    assert not (out / "run.json").exists() and not (out / "report.md").exists()
