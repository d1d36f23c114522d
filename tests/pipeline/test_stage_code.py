"""A stage kept from a run of other doefab code is reused as it is, and the run log, run.json and the report say
so with the flag that computes it again."""

import hashlib
import json
from pathlib import Path

import doefab
from doefab.io import sources_sha256

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
    from doefab.pipeline.report import _stage_items

    table = next(it[1] for it in _stage_items(scene, {"holder": other}, res) if it[0] == "table")
    assert "made by other doefab code: --force holder" in table[1][1]  # the report's Stages table says it
    rec = json.loads((tmp_path / "holder" / "stage.json").read_text())
    del rec["code"]  # a stage finished before runs recorded their code
    (tmp_path / "holder" / "stage.json").write_text(json.dumps(rec))
    monkeypatch.undo()
    monkeypatch.setitem(stagerun.STAGE_FUNCS, "holder", lambda *a: calls.append(1) or {"status": "ran"})
    assert _run(scene, res, tmp_path)["other_code"] and len(calls) == 1


def test_the_code_digest_is_of_the_installed_packages_sources():
    """The digest covers the doefab package that is imported (its folder found from ``doefab.__file__``), not an
    empty or other folder: a folder without sources would make every run look like the same code."""
    here = Path(doefab.__file__).resolve().parent
    assert stagerun.code_sha256() == sources_sha256(here.parent, ("doefab",))[:16]
    assert stagerun.code_sha256() != hashlib.sha256(b"").hexdigest()[:16]
    assert len(list(here.rglob("*.py"))) > 50
