"""A scene says where its tolerance parts run (``tolerance.workers``, ``tolerance.scheduler``): checked with the
scene, a ``tcp://`` scheduler reached before any stage (``doctor`` says the same), handed to the study, and a change
to either reruns nothing."""

import socket
from pathlib import Path
from types import SimpleNamespace

import pytest

from doefab.errors import DoefabError
from doefab.pipeline import stagerun, stages
from doefab.pipeline.scene import load_scene

REPO = Path(__file__).resolve().parents[2]


def _scene(tmp_path, extra: str, name: str = "hdr.toml"):
    text = (REPO / "scenes" / "hdr.toml").read_text()
    assert "[tolerance]" in text
    p = tmp_path / name
    p.write_text(text.replace("[tolerance]", "[tolerance]\n" + extra, 1))
    return p


@pytest.mark.parametrize("extra, words", [('scheduler = "local:0"', "tolerance.scheduler: 'local:0': local:N"),
                                          ('scheduler = "mars"', "tolerance.scheduler: 'mars' is not a Dask"),
                                          ("scheduler = 4", "tolerance.scheduler must be text in quotes"),
                                          ("workers = 0", "tolerance.workers = 0 is outside 1–64"),
                                          ('workers = 2\nscheduler = "local:2"', "both say where the parts run")])
def test_a_bad_runner_is_refused_with_the_scene(tmp_path, extra, words):
    with pytest.raises(DoefabError, match=words):
        load_scene(_scene(tmp_path, extra))


class _Stop(Exception):
    pass


def test_the_study_is_told_where_its_parts_run(tmp_path, monkeypatch):
    import doefab.tolerance.report as report

    seen = {}

    def spy(design_dir, budget, out, **kw):
        seen.update(kw)
        raise _Stop

    monkeypatch.setattr(report, "run_study", spy)
    for extra, want in [("workers = 3", (3, None)), ('scheduler = "local:2"', (None, "local:2")), ("", (None, None))]:
        with pytest.raises(_Stop):
            stages.stage_tolerance(load_scene(_scene(tmp_path, extra)), SimpleNamespace(reuse=True, sensor=None),
                                   tmp_path / "run" / "tolerance", True)
        assert (seen["workers"], seen["scheduler"]) == want


def test_where_the_parts_run_changes_no_stage_hash(tmp_path):
    res = SimpleNamespace(die_m=0.01)
    base = load_scene(_scene(tmp_path, "", "a.toml"))
    how = load_scene(_scene(tmp_path, 'scheduler = "local:4"', "b.toml"))
    c = _scene(tmp_path, "", "c.toml")
    c.write_text(c.read_text().replace("samples = 12", "samples = 7"))  # what the study computes
    what = load_scene(c)
    h = {s.path.name: stagerun.stage_hash(s, "tolerance", {}, False, res) for s in (base, how, what)}
    assert h["a.toml"] == h["b.toml"] != h["c.toml"]


def test_an_unreachable_scheduler_stops_run_before_any_stage_and_fails_doctor(tmp_path):
    from doefab.pipeline.doctor import _scheduler_rows
    from doefab.pipeline.run import prepare_scene

    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        scene = load_scene(_scene(tmp_path, f'scheduler = "tcp://127.0.0.1:{port}"'))
        prepare_scene(scene, tmp_path / "out")  # answers: accepted
        assert [r["ok"] for r in _scheduler_rows(scene.tolerance["scheduler"])] == [True]
    with pytest.raises(DoefabError, match="no Dask scheduler answers"):
        prepare_scene(scene, tmp_path / "out")
    (row,) = _scheduler_rows(scene.tolerance["scheduler"])
    assert not row["ok"] and "dask scheduler --port" in row["fix"]
    assert not (tmp_path / "out").exists()
    assert _scheduler_rows("local:2") == [] and _scheduler_rows(None) == []
