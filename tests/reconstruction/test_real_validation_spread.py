"""The shipping rule's run-to-run spread on the measured-data page (``benchmarks/real_validation.py``): the seeds
are read against the shipped network's score of their own run, whatever the shipped network scores now."""

import numpy as np
import pytest


def _real(scores, code="git a", budget="b1"):
    """A measured-set run of the HDR proposed network with these per-scene highlight PSNRs (dB)."""
    rows = [{"psnr_highlight": s} for s in scores]
    return {"task": "hdr", "images": 12, "size_px": 256, "real_sha256": {"hdr": "a", "definition": "x"},
            "code": code, "conditions": {"budget_sha256": budget},
            "rows": {"proposed": {"psnr_highlight": float(np.mean(scores))}},
            "per_image": {"rows": {"proposed": rows}}}


def _seed(value):
    """A seed's measured-set run, on the same 12 scenes as ``_real``'s."""
    return {"images": 12, "size_px": 256, "real_sha256": {"hdr": "a", "definition": "x"},
            "rows": {"proposed": {"psnr_highlight": value}}}


def test_seeds_scored_beside_the_same_scores_need_no_base(rv):
    committed = {"real": _real([40.0, 42.0]), "seeds": [_seed(41.5), _seed(40.5)]}
    seeds, base = rv.carried_seeds({"real": _real([40.0, 42.0 * (1 + 1e-8)])}, committed)
    assert seeds == committed["seeds"] and base is None


def test_a_rescored_network_keeps_its_seeds_with_the_score_they_were_read_beside(rv):
    """Re-scored at another budget (41.0 → 43.0 dB), the spread stays that of the three runs made together: seed 0
    at 41.0, seeds 41.5 and 40.5, SD 0.5; against the new 43.0 it would read 1.32."""
    committed = {"real": _real([40.0, 42.0]), "seeds": [_seed(41.5), _seed(40.5)]}
    now = {"real": _real([42.0, 44.0], code="git c", budget="b2")}
    seeds, base = rv.carried_seeds(now, committed)
    assert seeds == committed["seeds"] and base["rows"]["proposed"]["psnr_highlight"] == 41.0
    assert base["budget_sha256"] == "b1" and base["code"] == "git a"
    now["seed_base"] = base
    row = next(x for x in rv.spread_lines({"hdr": now}, {"hdr": seeds}) if x.startswith("| hdr"))
    assert row.split(" | ")[2:] == ["41", "41.5, 40.5", "41", "0.5 |"]
    # a later run keeps reading the seeds against the same base, not against the re-scored network
    again = rv.carried_seeds({"real": _real([42.0, 44.0], code="git d", budget="b2")}, {**now, "seeds": seeds})
    assert again[1] is base  # the committed base itself, not one rebuilt from the re-scored run


def test_fewer_than_three_seeds_measure_no_spread(rv):
    lines = rv.spread_lines({"hdr": {"real": _real([40.0])}}, {"hdr": [_seed(41.0)]})
    assert not any(x.startswith("| hdr") for x in lines) and "not measured" in lines[0]


def test_seeds_scored_on_other_scenes_are_refused(rv):
    """Seeds of 12 scenes are not read beside a shipped network scored on 13 (nor on another measured set)."""
    seeds = [_seed(41.5), _seed(40.5)]
    committed = {"real": _real([40.0, 42.0]), "seeds": seeds}
    for images, sha in ((13, "a"), (12, "b")):
        now = {"real": {**_real([40.0, 42.0]), "images": images, "real_sha256": {"hdr": sha, "definition": "x"}}}
        with pytest.raises(SystemExit, match="other measured scenes"):
            rv.carried_seeds(now, committed)
    now["real"].update(images=12, real_sha256={"hdr": "a", "definition": "y"})  # another realdata.py, same scenes
    assert rv.carried_seeds(now, committed) == (seeds, None)


def test_seeds_of_a_network_shipped_before_are_said_to_be_its_recipes(rv):
    """A network that replaced the one the seeds were trained beside keeps that spread, named as the earlier
    network's (its weights and steps), with the present network's own score beside it."""
    old = {**_real([40.0, 42.0]), "weights": {"proposed": {"sha256": "a" * 64, "steps": 500}}}
    committed = {"real": old, "seeds": [_seed(41.5), _seed(40.5)]}
    now = {"real": {**_real([42.0, 44.0], code="git c"), "weights": {"proposed": {"sha256": "b" * 64, "steps": 1000}}}}
    seeds, base = rv.carried_seeds(now, committed)
    assert base["weights"] == {"sha256": "a" * 64, "steps": 500} and base["rows"]["proposed"]["psnr_highlight"] == 41.0
    now["seed_base"] = base
    text = " ".join(rv.spread_lines({"hdr": now}, {"hdr": seeds}))
    assert "network shipped before this one (weights aaaaaaaaaaaa, 500 steps; its own score 41 in the row" in text
    assert "(1000 steps, bbbbbbbbbbbb, 43 in the table above)" in text
    assert "the present recipe's own spread over seeds is not measured" in text
    # the same network re-scored (same weights, another budget) keeps the plain wording: its own seeds
    now["real"]["weights"]["proposed"] = {"sha256": "a" * 64, "steps": 500}
    same = " ".join(rv.spread_lines({"hdr": now}, {"hdr": seeds}))
    assert "shipped before" not in same and "were scored at git a" in same
    # another network of as many steps is another network: told by its weights, not its steps
    now["real"]["weights"]["proposed"] = {"sha256": "c" * 64, "steps": 500}
    assert "shipped before this one" in " ".join(rv.spread_lines({"hdr": now}, {"hdr": seeds}))

