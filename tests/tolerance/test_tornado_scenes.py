"""The tornado's network rows are judged on the scenes the study asks for, as its error-free part and its
Monte Carlo parts are."""

from doefab.tolerance import study
from doefab.tolerance.errors import load_budget


def test_the_tornados_network_rows_are_judged_on_the_scenes_the_study_asks_for(monkeypatch, fake_judges):
    """``doefab run --quick`` judges its parts on 2 scenes of 128² px: the tornado's top errors (and the
    error-free part they are measured from) must be judged on those, not on the judge's default 8 of 256²."""
    settings = {"images": 2, "size": 128, "split": "test"}
    asked = []

    def evaluate(design_dir, supersample, errors, networks=False, weights_dir=None):
        asked.append(networks)
        out = {"metric": 0.5 - 0.001 * len(asked)}  # each error costs a different amount: a ranking exists
        if networks:
            out["network"] = {"nominal_psf": {"mae": 0.3}}
            out["network_scenes"] = {"nominal_psf": {"mae": [0.3, 0.3]}}
        return out

    monkeypatch.setattr(study, "evaluate_part", evaluate)
    rows = study.tornado("design", load_budget(None), networks=settings, network_top=2, progress=False)
    judged = [n for n in asked if n]
    assert judged, "no part was judged through the network"
    assert all(n == settings for n in judged), judged
    assert sum("network" in r for r in rows) == 2


def test_a_kept_tornado_is_judged_again_only_where_the_study_asked_for_other_scenes_than_the_defaults(tmp_path):
    """Tornadoes kept by earlier code judged their top errors (``network_top``) on the default scenes whatever the
    study asked for: those of a study on other scenes are computed again; the rest (default scenes, PSF level,
    every error through the network) are still reused."""
    from doefab.tolerance.report import _tornado_key, cached_step

    top, every = {"design": "d", "network_top": 2}, {"design": "d", "network_top": None}
    quick = {"images": 2, "size": 128, "split": "test"}
    cases = [(top, True, False), (top, {"images": 8, "size": 256, "split": "test"}, False), (top, False, False),
             (top, quick, True), (top, {"images": 8, "size": 256, "split": "val"}, True),
             (every, quick, False)]  # every error judged through the network: those rows had the study's scenes
    for i, (key, networks, again) in enumerate(cases):
        out = tmp_path / str(i)
        cached_step(out, "tornado", key, lambda: ["kept"])
        got = cached_step(out, "tornado", _tornado_key(key, networks), lambda: ["judged again"])
        assert got == (["judged again"] if again else ["kept"]), networks
