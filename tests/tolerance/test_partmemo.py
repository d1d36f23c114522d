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
