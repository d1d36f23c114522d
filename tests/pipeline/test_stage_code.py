"""A stage kept from a run of other doefab code is reused as it is, and the run log, run.json and the report say
so with the flag that computes it again."""

import json
from pathlib import Path

from doefab.pipeline import stagerun
from doefab.pipeline.scene import load_scene
from doefab.pipeline.stages import resolve

REPO = Path(__file__).resolve().parents[2]


def _run(scene, res, out):
    return stagerun.run_stage(scene, res, "holder", out, {}, quick=True, force=False)


def test_a_stage_made_by_other_code_is_kept_and_named(tmp_path, monkeypatch):
    scene = load_scene(REPO / "scenes" / "hdr.toml")
    res = resolve(scene)
    calls = []
    monkeypatch.setitem(stagerun.STAGE_FUNCS, "holder",
                        lambda *a: calls.append(1) or {"status": "ran", "why": "a stand-in stage"})
    first = _run(scene, res, tmp_path)
    assert first["code"] == stagerun.code_sha256() and len(calls) == 1
    assert stagerun.kept_note("holder", first) == ""
    same = _run(scene, res, tmp_path)
    assert len(calls) == 1 and same["reused_from_previous_run"] and not same["other_code"]
    assert stagerun.kept_note("holder", same) == "kept from the previous run"
    monkeypatch.setattr(stagerun, "code_sha256", lambda: "another version")
    other = _run(scene, res, tmp_path)
    assert len(calls) == 1 and other["other_code"]  # kept, not computed again
    assert "--force holder computes it again" in stagerun.kept_note("holder", other)
    rec = json.loads((tmp_path / "holder" / "stage.json").read_text())
    del rec["code"]  # a stage finished before runs recorded their code
    (tmp_path / "holder" / "stage.json").write_text(json.dumps(rec))
    monkeypatch.undo()
    monkeypatch.setitem(stagerun.STAGE_FUNCS, "holder", lambda *a: calls.append(1) or {"status": "ran"})
    assert _run(scene, res, tmp_path)["other_code"] and len(calls) == 1
