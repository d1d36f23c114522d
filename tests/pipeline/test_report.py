"""The report marks the committed design on the optimiser/grid benchmark only when it is one of those runs."""

import json

from doefab.pipeline.report import REPO, _committed_run


def test_committed_design_is_starred_only_when_it_is_a_benchmarked_run():
    for name in ("streak", "grating", "half-ring"):
        cfg = json.loads((REPO / "masks" / name / "design" / "design.json").read_text())["extra"]["config"]
        run, note = _committed_run(name)
        if cfg.get("parameterization", "pixel") == "pixel":
            assert run == ("adam, full grid" if cfg["sampling"] == 1 else "adam, half grid") and note == ""
        else:
            assert run is None and cfg["parameterization"] in note
    assert _committed_run("no-such-design") == (None, "")
