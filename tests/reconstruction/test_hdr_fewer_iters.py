"""The shipping rule's verdict on the HDR candidate page (``benchmarks/hdr_fewer_iters.py``)."""

import pytest


def _row(db, **more):
    return {"real": {"psnr_highlight": db, "psnr": 60.0}, "val": {"psnr_highlight": 26.0, "psnr": 42.0}, **more}


@pytest.mark.parametrize("candidate_db, verdict", [(43.81, "passes"), (43.8, "passes"), (43.79, "fails"),
                                                   (44.5, "passes")])
def test_a_candidate_passes_only_within_the_spread_below_the_shipped_network(hdr_candidates, candidate_db, verdict):
    """Read against the shipped score and spread of the candidate's own run (44.0, 0.2), not the page's latest."""
    against = {"shipped_db": 44.0, "spread_db": 0.2, "budget_sha256": "b1"}
    cand = _row(candidate_db, solve=[20, 20, 4], code="git x", seconds=0.6, shipped_seconds=1.2, against=against)
    res = {"shipped": _row(45.0), "spread_db": 0.01, "candidates": {"20_20_4": cand}}
    assert hdr_candidates.verdict(res, cand) == (pytest.approx(candidate_db - 44.0), verdict)
    text = hdr_candidates.markdown(res)
    head = f"20 + 20 in 4: {candidate_db - 44.0:+.2f} dB on the measured set against the shipped network's 44.00"
    assert head in text
    assert f"so it {verdict}; its reconstruction takes 0.50× the shipped network's time" in text
