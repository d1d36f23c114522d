"""The reconstruction speed table: its file is what its generator writes from its JSON, and its ratio column
pairs each round's two timings (this code's and the previous code's, measured in the same round)."""

import importlib
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"


def _speed(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    return importlib.import_module("reconstruction_speed")


def test_the_committed_speed_table_is_its_json(monkeypatch):
    r = json.loads((RESULTS / "reconstruction_speed.json").read_text())
    assert _speed(monkeypatch).table(r) == (RESULTS / "reconstruction_speed.md").read_text()


def test_the_ratio_column_pairs_the_timings_of_one_round(monkeypatch):
    speed = _speed(monkeypatch)

    def rounds(times):
        return [{t: {"reconstruct_s": s} for t in speed.TASKS} for s in times]

    # the machine's speed drifts from round to round; this code takes half the previous code's time in two rounds
    # and 2.5× in the third: the median of the rounds' ratios is 0.50, the ratio of the medians 1.25, and rounds
    # paired out of order give other values
    r = {"rounds": {"this_code": rounds([1.0, 4.0, 2.5]), "baseline": rounds([2.0, 8.0, 1.0])}}
    assert speed._ratio(r, "hdr") == "0.50"
    r["rounds"]["baseline"] = []
    assert speed._ratio(r, "hdr") == "—"
