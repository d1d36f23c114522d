"""``partmemo.PartMemo``: a study step's judged parts kept part by part, so an interrupted tornado resumes with them
and gives the rows an uninterrupted one gives, bit for bit."""

import json

import pytest

from doefab.tolerance.errors import load_budget
from doefab.tolerance.partmemo import PartMemo


def _counting(calls):
    def evaluate(design_dir, supersample, errors, networks=False, weights_dir=None):
        calls.append(errors["seed"])
        return {"metric": 0.1 + 0.01 * errors["seed"] + 1e-17, "nan": float("nan")}
    return evaluate


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

    def stopping(*args):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(args[2])
        return study.evaluate_part(*args)

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
    """``report._tornado_step``: interrupted, the parts judged so far stay in steps/tornado.parts.jsonl; resumed, they
    are read back; finished, the step is kept whole (steps/tornado.json) and the parts' file goes."""
    from doefab.tolerance.report import STEPS, _tornado_step

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
        _tornado_step(tmp_path, {"k": 1}, [], interrupted)
    assert (tmp_path / STEPS / "tornado.parts.jsonl").is_file() and calls == [1]
    rows = _tornado_step(tmp_path, {"k": 1}, [], finished)
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

    def stopping(*a):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(a[2])
        return real(*a)

    monkeypatch.setattr(study, "evaluate_part", stopping)
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
