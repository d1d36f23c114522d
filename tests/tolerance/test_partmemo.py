"""``partmemo.PartMemo``: a study step's judged parts kept part by part, so an interrupted tornado resumes with them
and gives the rows an uninterrupted one gives, bit for bit."""

import json

import numpy as np
import pytest

from doefab.tolerance.errors import load_budget
from doefab.tolerance.partmemo import PartMemo


def _counting(calls):
    def evaluate(design_dir, supersample, errors, networks=False, weights_dir=None):
        calls.append(errors["seed"])
        return {"metric": 0.1 + 0.01 * errors["seed"] + 1e-17, "nan": float("nan")}
    return evaluate


def _interrupted_at(n, calls, real, name=lambda *a: a):
    """``real`` that records ``name(*args)`` of each call it makes and is interrupted (Ctrl-C) at its ``n + 1``-th."""
    def stopping(*a):
        if len(calls) == n:
            raise KeyboardInterrupt
        calls.append(name(*a))
        return real(*a)
    return stopping


def test_a_part_judged_once_is_read_back_under_its_key_and_a_cut_line_is_judged_again(tmp_path):
    path, calls = tmp_path / "steps" / "t.parts.jsonl", []
    memo = PartMemo(path, {"design": "a"}, _counting(calls))
    first = [memo("d", 1, {"seed": s}) for s in (1, 2, 1)]
    assert calls == [1, 2] and first[0] == first[2] and first[0]["metric"] == 0.1 + 0.01 + 1e-17
    memo("d", 1, {"seed": 1})["metric"] = 0.0  # a caller changing what it was given
    assert memo("d", 1, {"seed": 1})["metric"] == 0.1 + 0.01 + 1e-17
    again = PartMemo(path, {"design": "a"}, _counting(calls))
    assert [again("d", 1, {"seed": s})["metric"] for s in (1, 2)] == [r["metric"] for r in first[:2]]
    assert calls == [1, 2] and again("d", 1, {"seed": 1})["nan"] != again("d", 1, {"seed": 1})["nan"]  # nan kept
    assert again("d", 2, {"seed": 1}) and calls == [1, 2, 1]  # another grid is another part
    with open(path, "a") as fh:
        fh.write('{"part": "cut')  # an interruption in the middle of a line
    cut = PartMemo(path, {"design": "a"}, _counting(calls))
    assert len(cut.done) == 3 and all(json.loads(line) for line in path.read_text().splitlines())
    other = PartMemo(path, {"design": "b"}, _counting(calls))  # another study's parts are not taken
    other("d", 1, {"seed": 1})
    assert calls == [1, 2, 1, 1] and len(path.read_text().splitlines()) == 2
    other.discard()
    assert not path.exists()


def test_an_interrupted_tornado_resumes_with_the_parts_it_judged(design_dir, tmp_path):
    """The PSF-level tornado of a small design interrupted at its fourth part, then resumed: the resumed run judges
    only the parts the first did not finish, and its rows are the uninterrupted tornado's to the last bit."""
    from doefab.tolerance import study

    budget = load_budget()
    whole = study.tornado(design_dir, budget, progress=False)
    path, key, calls = tmp_path / "tornado.parts.jsonl", {"study": 1}, []
    stopping = _interrupted_at(3, calls, study.evaluate_part, lambda *a: a[2])
    with pytest.raises(KeyboardInterrupt):
        study.tornado(design_dir, budget, progress=False, evaluate=PartMemo(path, key, stopping))
    resumed_calls = []

    def counting(*args):
        resumed_calls.append(args[2])
        return study.evaluate_part(*args)

    rows = study.tornado(design_dir, budget, progress=False, evaluate=PartMemo(path, key, counting))
    assert rows == whole
    assert not any(c in calls for c in resumed_calls) and len(calls) == 3 and resumed_calls  # none judged twice


def test_the_studys_tornado_step_keeps_its_parts_until_it_is_kept_whole(tmp_path):
    """``report.memo_step`` of the tornado: interrupted, the parts judged so far stay in steps/tornado.parts.jsonl;
    resumed, they are read back; finished, the step is kept whole (steps/tornado.json) and the parts' file goes."""
    from doefab.tolerance.report import STEPS, memo_step

    calls = []
    judge = _counting(calls)

    def interrupted(memo):
        memo._evaluate = judge
        memo("d", 1, {"seed": 1})
        raise KeyboardInterrupt

    def finished(memo):
        memo._evaluate = judge
        return [{"error": "etch", "delta": memo("d", 1, {"seed": s})["metric"]} for s in (1, 2)]

    with pytest.raises(KeyboardInterrupt):
        memo_step(tmp_path, "tornado", {"k": 1}, [], interrupted)
    assert (tmp_path / STEPS / "tornado.parts.jsonl").is_file() and calls == [1]
    rows = memo_step(tmp_path, "tornado", {"k": 1}, [], finished)
    assert calls == [1, 2] and [r["delta"] for r in rows] == [0.1 + 0.01 * s + 1e-17 for s in (1, 2)]
    assert (tmp_path / STEPS / "tornado.json").is_file() and not (tmp_path / STEPS / "tornado.parts.jsonl").exists()


def test_a_network_tornado_judges_its_psf_pass_and_its_network_pass_through_the_memo(monkeypatch, tmp_path,
                                                                                       fake_judges):
    """With ``network_top`` the tornado first ranks every error at PSF level, then judges the top ones through the
    network: both passes take their parts from the memo (a resumed network tornado judges no PSF-level part again)."""
    from doefab.tolerance import study

    asked = []

    def evaluate(design_dir, supersample, errors, networks=False, weights_dir=None):
        asked.append(bool(networks))
        out = {"metric": 0.5 - 0.001 * len(asked)}
        if networks:
            out["network"] = {"nominal_psf": {"mae": 0.3}}
            out["network_scenes"] = {"nominal_psf": {"mae": [0.3, 0.3]}}
        return out

    monkeypatch.setattr(study, "evaluate_part", lambda *a: (_ for _ in ()).throw(AssertionError("not memoised")))
    memo = PartMemo(tmp_path / "t.jsonl", {"k": 1}, evaluate)
    rows = study.tornado("design", load_budget(None), networks=True, network_top=2, progress=False, evaluate=memo)
    assert False in asked and True in asked and sum("network" in r for r in rows) == 2


def test_an_interrupted_studys_tornado_resumes_part_by_part(design_dir, tmp_path, monkeypatch):
    """``run_study`` interrupted in its tornado keeps the parts judged so far; the rerun judges only the others, its
    tornado is an uninterrupted study's, and the parts' file is gone once the tornado is kept whole."""
    from doefab.tolerance import study
    from doefab.tolerance.report import STEPS, run_study

    real, calls, again = study.evaluate_part, [], []
    monkeypatch.setattr(study, "evaluate_part", _interrupted_at(3, calls, real, lambda *a: a[2]))
    out = tmp_path / "o"
    with pytest.raises(KeyboardInterrupt):
        run_study(design_dir, load_budget(), out, samples=0, grid=1, progress=False)
    assert (out / STEPS / "tornado.parts.jsonl").is_file()
    monkeypatch.setattr(study, "evaluate_part", lambda *a: again.append(a[2]) or real(*a))
    res = run_study(design_dir, load_budget(), out, samples=0, grid=1, progress=False)
    assert again and not any(c in calls for c in again)
    assert not (out / STEPS / "tornado.parts.jsonl").exists()
    monkeypatch.setattr(study, "evaluate_part", real)
    assert res["tornado"] == run_study(design_dir, load_budget(), tmp_path / "w", samples=0, grid=1,
                                       progress=False)["tornado"]


def test_a_step_that_kept_no_part_leaves_no_file(tmp_path):
    """A memo opened and left before any part (or over a file of another key) leaves no parts file behind, not even a
    folder: an empty one would read as progress (``pipeline.stagerun.has_progress``)."""
    path = tmp_path / "steps" / "grid.parts.jsonl"
    PartMemo(path, {"k": 1})
    assert not path.parent.exists()
    PartMemo(path, {"k": 1}).keep("mask overlay", lambda: {"grid": 2})
    assert len(path.read_text().splitlines()) == 2
    PartMemo(path, {"k": 2})  # another study's key: its file is started afresh, with its first part
    assert not path.exists()


def test_keep_reads_a_named_part_back_as_a_resumed_run_reads_it(tmp_path):
    """``PartMemo.keep``: a part the step names is computed once, read back by a resumed step of the same key, and
    handed out as JSON reads it back (a whole-number key as text) both times, so a fresh and a resumed step agree."""
    path, calls = tmp_path / "q.parts.jsonl", []

    def row(n):
        calls.append(n)
        return {"levels": n, "bound": {1: 0.25 + n * 1e-17}, "worst": float("nan")}

    memo = PartMemo(path, {"k": 1})
    first = [memo.keep(f"levels {n}", lambda: row(n)) for n in (8, 4, 8)]
    assert calls == [8, 4] and first[0] == {**first[2], "worst": first[0]["worst"]}
    assert first[0]["bound"] == {"1": 0.25 + 8e-17} and first[0]["worst"] != first[0]["worst"]  # NaN kept
    first[0]["levels"] = 0  # a caller changing what it was given changes no kept part
    assert memo.keep("levels 8", lambda: row(8))["levels"] == 8
    again = PartMemo(path, {"k": 1})
    assert [again.keep(f"levels {n}", lambda: row(n))["bound"] for n in (8, 4)] == [{"1": 0.25 + n * 1e-17}
                                                                                    for n in (8, 4)]
    assert again.keep("levels 8", lambda: row(8))["levels"] == 8 and calls == [8, 4]


def _stopping(n, calls, keep):
    """``keep`` that records the parts it is asked for and is interrupted when asked for the ``n + 1``-th."""
    return _interrupted_at(n, calls, keep, lambda name, compute: name)


def _computing(seen, keep):
    """``keep`` that records each part it computes (not the ones it reads back)."""
    return lambda name, compute: keep(name, lambda: seen.append(name) or compute())


def test_an_interrupted_sweep_resumes_with_the_magnitudes_it_judged(design_dir, tmp_path):
    """The sweeps of two error kinds interrupted at their fourth magnitude, then resumed through a memo: only the
    others are judged, and the rows are the uninterrupted sweeps' (as JSON reads them back) to the last bit."""
    from doefab.io import from_json_ready, json_ready
    from doefab.tolerance import study

    names = study.sweep_names()[:2]
    whole = study.sweep(design_dir, names=names, progress=False)["sweeps"]
    path, asked, judged = tmp_path / "sweeps.parts.jsonl", [], []
    with pytest.raises(KeyboardInterrupt):
        study.sweep(design_dir, names=names, progress=False, keep=_stopping(3, asked, PartMemo(path, {"k": 1}).keep))
    resumed = study.sweep(design_dir, names=names, progress=False,
                          keep=_computing(judged, PartMemo(path, {"k": 1}).keep))
    assert len(asked) == 3 and judged and not set(asked) & set(judged)
    assert len(judged) == sum(len(v["rows"]) for v in whole.values()) - 3
    assert resumed["sweeps"] == from_json_ready(json.loads(json.dumps(json_ready(whole))))


def test_an_interrupted_studys_quantization_resumes_level_by_level(design_dir, tmp_path, monkeypatch):
    """``run_study`` interrupted in its quantization study keeps the level counts judged so far; the rerun judges only
    the others, its rows are an uninterrupted study's, and the parts' file is gone once the step is kept whole."""
    from doefab.tolerance import study
    from doefab.tolerance.report import STEPS, run_study

    real, calls, again = study._quantized_row, [], []
    monkeypatch.setattr(study, "_quantized_row", _interrupted_at(2, calls, real, lambda *a: a[3]))
    out, budget = tmp_path / "o", load_budget()
    with pytest.raises(KeyboardInterrupt):
        run_study(design_dir, budget, out, samples=0, grid=1, do_levels=True, progress=False)
    assert (out / STEPS / "quantization.parts.jsonl").is_file() and (out / STEPS / "tornado.json").is_file()
    monkeypatch.setattr(study, "_quantized_row", lambda *a: again.append(a[3]) or real(*a))
    res = run_study(design_dir, budget, out, samples=0, grid=1, do_levels=True, progress=False)
    assert again and not set(calls) & set(again) and "quantization" not in res["steps_reused"]
    assert "quantization (in part)" in res["steps_reused"]
    assert "tornado" in res["steps_reused"] and not (out / STEPS / "quantization.parts.jsonl").exists()
    monkeypatch.setattr(study, "_quantized_row", real)
    whole = study.quantization_study(design_dir, supersample=1, progress=False)
    assert len(calls) + len(again) == len(whole) and res["quantization"] == whole
    assert (out / STEPS / "quantization.json").is_file()


def test_an_interrupted_grid_study_resumes_kind_by_kind(design_dir, tmp_path, monkeypatch):
    """The grid study (``grid="auto"``) interrupted after its first error kind, then resumed: the rerun judges only the
    other kinds, and the record is an uninterrupted study's (the first kind's bounds as that run judged them)."""
    from doefab.tolerance import grid as grid_mod
    from doefab.tolerance.kinds import kind
    from doefab.tolerance.report import STEPS, _grid_record
    from doefab.tolerance.partmemo import PartMemo as Memo
    from doefab.tolerance.study import judge_for

    judge, budget, path = judge_for(str(design_dir), 1), load_budget(), tmp_path / STEPS / "grid.parts.jsonl"
    asked, judged, real = [], [], grid_mod.grid_study
    monkeypatch.setattr(grid_mod, "grid_study", lambda j, b, **kw: real(j, b, **{**kw, "keep": _stopping(
        1, asked, kw["keep"])}))
    with pytest.raises(KeyboardInterrupt):
        _grid_record(judge, budget, "auto", False, Memo(path, {"k": 1}))
    monkeypatch.setattr(grid_mod, "grid_study", lambda j, b, **kw: real(j, b, **{**kw, "keep": _computing(
        judged, kw["keep"])}))
    rec = _grid_record(judge, budget, "auto", False, Memo(path, {"k": 1}))
    assert len(asked) == 1 and judged and asked[0] not in judged and set(rec["kinds"]) == set(asked + judged)
    monkeypatch.setattr(grid_mod, "grid_study", real)
    whole = _grid_record(judge, budget, "auto", False, Memo(tmp_path / "whole.parts.jsonl", {"k": 2}))
    assert {k: {f: x for f, x in v.items() if f != "seconds"} for k, v in rec["kinds"].items()} == \
        {k: {f: x for f, x in v.items() if f != "seconds"} for k, v in whole["kinds"].items()}
    assert rec["monte_carlo_grid"] == whole["monte_carlo_grid"]
    for name, row in rec["kinds"].items():  # each kind's row is its own: judged at its own budget value
        k = kind(name)
        assert row["value"] == k.from_budget(budget) / k.si and row["unit"] == k.unit


def test_an_interrupted_surrogate_resumes_with_the_parts_it_judged(design_dir, tmp_path, monkeypatch):
    """The surrogate interrupted in its calibration (after its fit's parts), then resumed: the parts judged before
    are read back (none judged twice), and the fit, its yield and its validation (on held-out parts of its own:
    the study has no Monte Carlo parts) are an uninterrupted one's; both steps are then kept whole."""
    from doefab.applications import of_design
    from doefab.tolerance import report, study

    judge, budget = study.judge_for(str(design_dir), 1), load_budget()
    real, asked, again = judge.evaluate, [], []
    res = {"nominal": {"psf": {"psf_metric": judge.score(judge.nominal)["metric"]}}}
    args = (res, design_dir, budget, 1, budget.get("spec", {}), of_design(judge.design.task).name, False)
    whole = report._surrogate(tmp_path / "whole", {"k": 1}, [], *args)
    stop = whole["model"]["parts"] + 3  # in the calibration, after the fit's parts
    monkeypatch.setattr(judge, "evaluate", _interrupted_at(stop, asked, real, lambda part: part))
    with pytest.raises(KeyboardInterrupt):
        report._surrogate(tmp_path, {"k": 1}, [], *args)
    monkeypatch.setattr(judge, "evaluate", lambda part: again.append(part) or real(part))
    reused = []
    got = report._surrogate(tmp_path, {"k": 1}, reused, *args)
    assert len(asked) == stop and again and not any(p in asked for p in again)
    assert reused == ["surrogate" + report.IN_PART]
    assert not list((tmp_path / report.STEPS).glob("*.parts.jsonl"))
    assert {p.name for p in (tmp_path / report.STEPS).iterdir()} == {"surrogate.json", "surrogate_holdout.json"}
    drop = ("seconds", "seconds_total")
    assert {k: v for k, v in got["model"].items() if k not in drop} == \
        {k: v for k, v in whole["model"].items() if k not in drop}
    assert got["yield"] == whole["yield"] and got["validation"] == whole["validation"]
    assert got["validation"]["parts"] == "held-out parts of its own"


def test_an_interrupted_studys_sweeps_resume_and_the_report_says_so(design_dir, tmp_path, monkeypatch):
    """``run_study`` interrupted in its sweeps keeps the magnitudes judged; the rerun judges only the others, its
    sweeps are an uninterrupted study's, and its report says which steps it took whole and which in part."""
    from doefab.tolerance import study
    from doefab.tolerance.report import IN_PART, run_study

    real, asked, judged = study.sweep, [], []
    monkeypatch.setattr(study, "sweep", lambda *a, keep, **k: real(*a, keep=_stopping(4, asked, keep), **k))
    out, budget = tmp_path / "o", load_budget()
    with pytest.raises(KeyboardInterrupt):
        run_study(design_dir, budget, out, samples=0, grid=1, do_sweep=True, progress=False)
    monkeypatch.setattr(study, "sweep", lambda *a, keep, **k: real(*a, keep=_computing(judged, keep), **k))
    res = run_study(design_dir, budget, out, samples=0, grid=1, do_sweep=True, progress=False)
    assert len(asked) == 4 and judged and not set(asked) & set(judged)
    assert res["steps_reused"] == ["grid", "tornado", "sweeps" + IN_PART] and res["sweep_seconds"] is not None
    report = (out / "report.md").read_text()
    assert "Reused from an earlier run of the same study: grid, tornado" in report
    assert "Resumed with the parts the interrupted run judged: sweeps" in report
    monkeypatch.setattr(study, "sweep", real)
    assert res["sweeps"] == run_study(design_dir, budget, tmp_path / "w", samples=0, grid=1, do_sweep=True,
                                      progress=False)["sweeps"]


def test_the_quantization_step_is_keyed_by_its_grid_and_the_designs_continuous_heights(monkeypatch, design_dir):
    """The quantization study's rows depend on the grid and on the continuous heights the design folder keeps (which
    its level map does not fix): a study resumed on another grid or with other heights does not take the kept rows."""
    from doefab.tolerance import report, study

    keys = []
    monkeypatch.setattr(report, "memo_step", lambda out, name, key, reused, compute: keys.append(key) or [])
    judge = study.judge_for(str(design_dir), 1)
    for grid, height in ((1, None), (2, None), (1, np.ones((4, 4))), (1, np.ones((4, 4)) * 2)):
        monkeypatch.setattr(study, "continuous_height", lambda design, h=height: h)
        report._quantization("o", {"study": 1}, [], judge, design_dir, grid, False, None, False)
    assert all(k["study"] == 1 for k in keys) and len({json.dumps(k, sort_keys=True) for k in keys}) == 4
