"""The delivered quality's statistics: variance components of a parts × scenes table against the values that made
it, and the two-level bootstrap against the part-level one and the analytic spread of a crossed design."""

import math

import numpy as np
import pytest

from doefab.tolerance.delivered import bootstrap, change_noise, delivered_summary, variance_components


def _table(parts=12, scenes=8, part_sd=0.5, scene_sd=0.0, noise_sd=0.0, seed=1):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(0, part_sd, parts), rng.normal(0, scene_sd, scenes)
    return 30.0 + a[:, None] + b[None, :] + rng.normal(0, noise_sd, (parts, scenes)), a, b


def test_components_of_an_additive_table_are_its_parts_and_scenes_spreads_exactly():
    x, a, b = _table(scene_sd=2.0)
    c = variance_components(x)
    assert c["part_sd"] == pytest.approx(np.std(a, ddof=1), rel=1e-9)
    assert c["scene_sd"] == pytest.approx(np.std(b, ddof=1), rel=1e-9)
    assert c["interaction_sd"] == pytest.approx(0.0, abs=1e-9) and c["scenes_needed"] == 1
    assert c["common_noise_sd"] == pytest.approx(np.std(b, ddof=1) / math.sqrt(8), rel=1e-9)


def test_components_recover_the_spreads_that_made_a_noisy_table():
    """400 parts × 20 scenes drawn with part 0.3, scene 2 and interaction 1.5: the part and scene spreads are
    those of the drawn part and scene values (the interaction's share of the parts' means taken out), the
    interaction its 1.5; a part's scene noise is 1.5/√20, and 1.5²/0.3² = 25 → 26 scenes put it below the part
    spread."""
    x, a, b = _table(parts=400, scenes=20, part_sd=0.3, scene_sd=2.0, noise_sd=1.5, seed=3)
    c = variance_components(x)
    assert c["part_sd"] == pytest.approx(np.std(a, ddof=1), rel=0.1)
    assert c["scene_sd"] == pytest.approx(np.std(b, ddof=1), rel=0.02)
    assert c["interaction_sd"] == pytest.approx(1.5, rel=0.03)
    assert c["part_noise_sd"] == pytest.approx(c["interaction_sd"] / math.sqrt(20), rel=1e-9)
    assert c["scenes_needed"] == int(c["interaction_sd"] ** 2 // c["part_sd"] ** 2) + 1
    assert 20 <= c["scenes_needed"] <= 32
    nan_scene = x.copy()
    nan_scene[3, 7] = np.nan  # a scene some part leaves undefined drops out
    assert variance_components(nan_scene)["scenes"] == 19


def _passes(limit):
    return lambda means, nominal: means[:, 0] >= (nominal[0] - limit if nominal is not None else limit)


def test_without_scene_noise_the_two_level_bootstrap_is_the_part_level_one():
    x, _, _ = _table()
    x = x[:, :, None]
    two = bootstrap(x, _passes(29.8), draws=500, seed=4)
    one = bootstrap(x, _passes(29.8), draws=500, seed=4, scenes=False)
    assert two == {**one, "scenes_resampled": True}
    assert one["mean"] == pytest.approx(x.mean()) and one["yield"] == pytest.approx(np.mean(x[:, 0, 0] >= 29.8))
    # and it is the ordinary bootstrap of the parts' values
    rng = np.random.default_rng(np.random.SeedSequence([4, 0]))
    means = [x[rng.integers(12, size=12), 0, 0].mean() for _ in range(500)]
    assert one["mean_ci95"] == pytest.approx(list(np.percentile(means, [2.5, 97.5])))


def test_scene_noise_widens_the_intervals_as_a_crossed_design_predicts():
    """40 parts (spread 0.1) on 30 shared scenes whose difficulty spreads 3: the mean's two-level interval is
    about 2 × 1.96 × 3/√30 wide (the scene set's common offset), the part-level one about 2 × 1.96 × 0.1/√40; the
    yield against a limit 0.05 below the error-free part on the same scenes barely moves (the offset cancels),
    against an absolute limit it spreads over most of 0–1."""
    x, _, b = _table(parts=40, scenes=30, part_sd=0.1, scene_sd=3.0, noise_sd=0.02, seed=5)
    x = x[:, :, None]
    nominal = (30.0 + b)[:, None]
    two = bootstrap(x, _passes(0.05), nominal, draws=1000, seed=6)
    one = bootstrap(x, _passes(0.05), nominal, draws=1000, seed=6, scenes=False)
    width = two["mean_ci95"][1] - two["mean_ci95"][0]
    expected = 2 * 1.96 * math.sqrt(np.var(b, ddof=1) / 30 + 0.1 ** 2 / 40)
    assert width == pytest.approx(expected, rel=0.2)
    assert one["mean_ci95"][1] - one["mean_ci95"][0] == pytest.approx(2 * 1.96 * 0.1 / math.sqrt(40), rel=0.3)
    relative = two["yield_ci95"][1] - two["yield_ci95"][0]
    assert relative <= 1.3 * (one["yield_ci95"][1] - one["yield_ci95"][0]) + 0.05
    absolute = bootstrap(x, _passes(float(np.median(x))), None, draws=1000, seed=6)
    assert absolute["yield_ci95"][1] - absolute["yield_ci95"][0] > 0.6


def test_the_summary_yield_is_the_parts_share_and_its_interval_holds_wilsons():
    """Per label: the yield is the share of parts whose scene mean meets the spec against the error-free part's
    scene mean (as ``summarize`` counts it), and its interval joins the bootstrap's with Wilson's, which stays
    open at a yield of 1."""
    from doefab.tolerance.yieldstats import summarize, wilson

    x, _, b = _table(parts=10, scenes=4, part_sd=0.3, scene_sd=1.0, noise_sd=0.1, seed=7)
    samples = [{"metric": 0.8, "worst": 0.7, "l1_to_nominal": 0.1,
                "network": {"nominal_psf": {"psnr_highlight": float(r.mean()), "psnr": 40.0}},
                "network_scenes": {"nominal_psf": {"psnr_highlight": list(r), "psnr": [40.0] * 4}}} for r in x]
    nominal = {"psnr_highlight": list(30.0 + b), "psnr": [40.0] * 4}
    spec = {"hdr": {"psnr_highlight_db_loss_max": 0.2}}
    got = delivered_summary(samples, {"nominal_psf": nominal}, spec, "hdr")["nominal_psf"]
    old = summarize(samples, spec, "hdr", {"psf": {}, "network": {"nominal_psf": {
        "psnr_highlight": float(np.mean(nominal["psnr_highlight"])), "psnr": 40.0}}})
    assert got["yield"] == old["network"]["nominal_psf"]["yield"]["value"]
    assert got["mean"] == pytest.approx(x.mean())
    lo, hi = got["yield_ci95"]
    assert lo <= min(got["bootstrap_yield_ci95"][0], got["wilson_ci95"][0]) + 1e-12
    assert hi >= max(got["bootstrap_yield_ci95"][1], got["wilson_ci95"][1]) - 1e-12
    everyone = delivered_summary(samples, {"nominal_psf": nominal}, {"hdr": {"psnr_highlight_db_loss_max": 50.0}},
                                 "hdr")["nominal_psf"]
    assert everyone["yield"] == 1.0 and everyone["bootstrap_yield_ci95"] == [1.0, 1.0]
    assert everyone["yield_ci95"] == pytest.approx([wilson(10, 10)[0], 1.0])
    assert got["components"]["parts"] == 10 and got["components"]["scenes"] == 4


def test_the_report_states_the_delivered_yield_its_interval_and_the_scene_noise_against_the_spread():
    """The summary's opening takes the delivered mean's and yield's intervals over parts and scenes; its list
    gives the delivered-quality yield with both intervals and says whether a part's scene noise lies below the
    part-to-part spread, or how many scenes would put it there."""
    from doefab.tolerance.yieldstats import summarize
    from doefab.tolerance.reporttext import lead_text, summary_lines

    def res_for(noise_sd, parts=10):
        x, _, b = _table(parts=parts, scenes=4, part_sd=0.5, scene_sd=1.0, noise_sd=noise_sd, seed=8)
        samples = [{"metric": 0.85, "worst": 0.8, "l1_to_nominal": 0.1,
                    "network": {"nominal_psf": {"psnr_highlight": float(r.mean())}},
                    "network_scenes": {"nominal_psf": {"psnr_highlight": list(r)}}} for r in x]
        scenes = {"nominal_psf": {"psnr_highlight": list(30.2 + b)}}
        nominal = {"psf": {"psf_metric": 0.869}, "network": {"nominal_psf": {"psnr_highlight": 30.2 + b.mean()}}}
        spec = {"hdr": {"psf_metric_min": 0.8, "psnr_highlight_db_loss_max": 0.5}}
        summary = summarize(samples, spec, "hdr", nominal)
        summary["delivered"] = delivered_summary(samples, scenes, spec, "hdr")
        return {"task": "hdr", "summary": summary, "nominal": nominal, "budget": {"spec": spec}, "tornado": [],
                "stop": "the DOE", "network_judge": {"images": 4, "size": 256, "split": "test"}}, summary

    res, s = res_for(0.05)
    d = s["delivered"]["nominal_psf"]
    lead = lead_text(res)
    assert f"(95 % interval of the mean over parts and scenes {d['mean_ci95'][0]:.2f}–{d['mean_ci95'][1]:.2f} dB" in lead
    lo, hi = d["yield_ci95"]
    assert f"{100 * d['yield']:.0f} % of the parts (95 % interval over parts and scenes {100 * lo:.0f}–{100 * hi:.0f} %)" in lead
    (line,) = [x for x in summary_lines(res) if x.startswith("- **Delivered-quality yield**")]
    assert f"{d['yield']:.2f}, 95 % interval {lo:.2f}–{hi:.2f} over parts and scenes" in line
    assert "4 test scenes of 256² px per part" in line and ": below it (point estimates);" in line
    noisy, s = res_for(1.2, parts=150)  # many parts resolve the spread that 4 scenes blur on each part
    (line,) = [x for x in summary_lines(noisy) if x.startswith("- **Delivered-quality yield**")]
    c = s["delivered"]["nominal_psf"]["components"]
    assert c["parts_differ_p"] < 0.05 and c["scenes_needed"] > 4
    assert f"NOT below it: judge each part on at least {c['scenes_needed']} scenes (a point estimate)" in line
    blurred, s = res_for(1.2)  # 10 parts on 4 scenes: the F test does not tell the parts apart
    (line,) = [x for x in summary_lines(blurred) if x.startswith("- **Delivered-quality yield**")]
    p = s["delivered"]["nominal_psf"]["components"]["parts_differ_p"]
    assert p > 0.05 and f"not resolved by these scenes (F test of the parts p = {p:.2f})" in line


def test_when_no_error_judged_through_the_network_costs_delivered_quality_the_psf_metric_says_what_limits():
    """On a few scenes the judged errors can leave the delivered metric unchanged or better: the summary then
    ranks by the PSF metric and says that no judged error lowered the delivered one, rather than naming nothing."""
    from doefab.tolerance.reporttext import lead_text, summary_lines

    gain = {"nominal_psf": {"psnr_highlight": 0.13, "psnr": 0.1}, "measured_psf": {"psnr_highlight": 0.1, "psnr": 0.1}}
    rows = [{"error": "mask overlay", "value": 0.707, "unit": "µm rms length", "grid": 1, "metric": 0.81,
             "delta": -0.062, "network_delta": gain},
            {"error": "decenter across split", "value": 0.144, "unit": "mm", "grid": 1, "metric": 0.83,
             "delta": -0.042, "network_delta": gain},
            {"error": "edge bias", "value": 0.1, "unit": "µm", "grid": 1, "metric": 0.85, "delta": -0.018}]
    res = {"task": "hdr", "tornado": rows, "stop": "the DOE", "budget": {"spec": {}}, "nominal": {"psf": {}}}
    lines = summary_lines(res)
    assert ("- **Limited by** (PSF metric; no error of the 2 judged through the network lowered the delivered "
            "highlight PSNR on the judge's scenes) mask overlay at 0.707 µm rms length (-0.062); decenter across "
            "split at 0.144 mm (-0.042); edge bias at 0.1 µm (-0.018).") in lines
    assert any(x.startswith("- **Would buy the most:** a better aligner") and "(recovers up to 0.062 of the PSF metric)"
               in x for x in lines)
    rows[1]["network_delta"] = {"nominal_psf": {"psnr_highlight": -0.4, "psnr": 0.0}}
    lines = summary_lines(res)
    assert any(x.startswith("- **Limited by** (delivered highlight PSNR, network told the nominal PSF; the 2 errors "
                            "that cost the most PSF metric were judged through the network) decenter across split")
               for x in lines)
    assert lead_text(res) is None  # no Monte Carlo: no opening paragraph


def test_a_single_parts_change_carries_the_95_percent_interval_of_its_paired_scene_changes():
    """``change_noise``: the half-width of a paired t interval of part − base over the scenes, as scipy's paired
    t-test gives it; a scene undefined for either is left out; under two scenes, None."""
    from scipy.stats import ttest_rel

    rng = np.random.default_rng(3)
    base = rng.normal(29.0, 3.0, 8)
    part = base + rng.normal(-0.2, 0.4, 8)
    lo, hi = ttest_rel(part, base).confidence_interval(0.95)
    got = change_noise({"nominal_psf": {"psnr": list(part - base)}})
    assert got["nominal_psf"]["psnr"] == pytest.approx((hi - lo) / 2, rel=1e-9)
    holed = part.copy()
    holed[2] = np.nan  # a scene without highlights: no value for this part
    lo, hi = ttest_rel(np.delete(part, 2), np.delete(base, 2)).confidence_interval(0.95)
    got = change_noise({"a": {"m": list(holed - base)}})["a"]["m"]
    assert got == pytest.approx((hi - lo) / 2, rel=1e-9)
    assert change_noise({"a": {"m": [0.5, np.nan]}})["a"]["m"] is None


def test_a_delivered_change_inside_its_scene_noise_ranks_nothing():
    """A tornado row's delivered loss names what limits the part only where the judge's scenes resolve it (beyond
    its 95 % interval): inside it, the PSF metric ranks and the report says why; beyond it, the loss is named with
    its ±. The tornado table gives each change's ± and says what it means."""
    from doefab.tolerance.reporttext import NOISE_NOTE, body_lines, lead_text, summary_lines

    def row(name, delta, loss, noise):
        return {"error": name, "value": 1.0, "unit": "µm", "grid": 1, "metric": 0.8 + delta, "delta": delta,
                "network_delta": {"nominal_psf": {"psnr_highlight": -loss, "psnr": 0.0},
                                  "measured_psf": {"psnr_highlight": 0.0, "psnr": 0.0}},
                "network_delta_ci95": {"nominal_psf": {"psnr_highlight": noise, "psnr": 0.1},
                                       "measured_psf": {"psnr_highlight": noise, "psnr": 0.1}}}

    samples = [{"metric": 0.85, "worst": 0.8, "l1_to_nominal": 0.1}] * 3
    from doefab.tolerance.yieldstats import summarize

    nominal = {"psf": {"psf_metric": 0.869}}
    res = {"task": "hdr", "stop": "the DOE", "warnings": [], "budget": {"spec": {}}, "nominal": nominal,
           "level": "network", "grid": {"fixed": True, "monte_carlo_grid": 1},
           "summary": summarize(samples, {}, "hdr", nominal),
           "tornado": [row("mask overlay", -0.06, 0.1, 1.0), row("mount rotation", -0.01, 0.36, 1.0)]}
    text = "\n".join(summary_lines(res))
    limited = text.split("Limited by")[1].split("\n")[0]
    assert limited.startswith("** (PSF metric; no error of the 2 judged through the network lowered the delivered "
                              "highlight PSNR by more than the scene noise")
    assert limited.index("mask overlay") < limited.index("mount rotation")  # the PSF metric's order
    assert "no error judged through the network lowered what the part delivers by more than the judge's scene " \
           "noise" in lead_text(res)
    body = "\n".join(body_lines(res))
    assert "highlight PSNR -0.36 ± 1 dB" in body and NOISE_NOTE in body
    res["tornado"][1]["network_delta_ci95"]["nominal_psf"]["psnr_highlight"] = 0.2  # now resolved
    limited = "\n".join(summary_lines(res)).split("Limited by")[1].split("\n")[0]
    assert limited.startswith("** (delivered highlight PSNR") and "mount rotation at 1 µm (0.36 ± 0.2 dB worse)" in limited
    assert "mask overlay" not in limited  # its 0.1 dB is inside its ±1 dB
    assert "costs 0.36 dB of highlight PSNR, ± 0.20 dB over the judge's scenes" in lead_text(res)


def test_for_depth_a_resolved_mae_increase_limits_and_a_resolved_gain_does_not():
    """Lower is better for depth MAE: an increase beyond its ± is a loss that names the limit; a decrease beyond its
    ± is a gain, never a limit, and leaves the PSF metric to rank when nothing else is resolved."""
    from doefab.tolerance.reporttext import summary_lines

    def row(name, delta, dmae, noise):
        return {"error": name, "value": 1.0, "unit": "mm", "grid": 1, "metric": 0.4 + delta, "delta": delta,
                "network_delta": {"nominal_psf": {"mae": dmae, "delta125": 0.0}},
                "network_delta_ci95": {"nominal_psf": {"mae": noise, "delta125": None}}}

    res = {"task": "depth", "stop": "the DOE", "warnings": [], "budget": {}, "nominal": {"psf": {"psf_metric": 0.4}},
           "tornado": [row("mask overlay", -0.05, 0.02, 0.03), row("decenter across split", -0.02, 0.2, 0.05)]}
    limited = "\n".join(summary_lines(res)).split("Limited by")[1].split("\n")[0]
    assert "decenter across split at 1 mm (0.2 ± 0.05 m worse)" in limited and "mask overlay" not in limited
    res["tornado"][1]["network_delta"]["nominal_psf"]["mae"] = -0.2  # a resolved gain: no limit
    limited = "\n".join(summary_lines(res)).split("Limited by")[1].split("\n")[0]
    assert limited.startswith("** (PSF metric; no error of the 2 judged through the network lowered the delivered "
                              "depth MAE by more than the scene noise")


def test_the_mean_interval_covers_the_population_mean_as_often_as_it_says():
    """Tables drawn from a crossed design whose scenes dominate (24 parts, 8 scenes, as the studies judge): the
    t interval over parts and scenes holds the population mean in about 95 % of the draws; the percentile
    bootstrap over the same 8 scenes in fewer."""
    from doefab.tolerance.delivered import mean_interval

    rng = np.random.default_rng(11)
    n = 400

    def coverage(parts, scenes, part_sd, scene_sd, noise_sd, boot=0):
        hits = boot_hits = 0
        for i in range(n):
            a, b = rng.normal(0, part_sd, parts), rng.normal(0, scene_sd, scenes)
            x = 30.0 + a[:, None] + b[None, :] + rng.normal(0, noise_sd, (parts, scenes))
            lo, hi = mean_interval(float(x.mean()), variance_components(x))
            hits += lo <= 30.0 <= hi
            if i < boot:
                bl, bh = bootstrap(x[:, :, None], None, draws=300, seed=i)["mean_ci95"]
                boot_hits += bl <= 30.0 <= bh
        return hits / n, boot_hits / max(boot, 1)

    scenes_rule, boot = coverage(24, 8, 0.4, 12.0, 1.1, boot=100)
    assert 0.92 <= scenes_rule <= 0.98 and boot < scenes_rule - 0.03
    # parts dominating, parts and scenes alike on a small table: each term of the variance must be there
    for parts, scenes, part_sd, scene_sd in ((24, 8, 1.0, 0.1), (6, 8, 1.0, 1.0)):
        assert 0.92 <= coverage(parts, scenes, part_sd, scene_sd, 0.5)[0] <= 0.98
    # the interaction alone: counted once (the floor at its own share makes the interval a little wide there)
    assert 0.93 <= coverage(6, 4, 0.0, 0.0, 0.5)[0] <= 0.99


def test_the_f_test_tells_parts_that_differ_from_parts_that_do_not():
    rng = np.random.default_rng(12)
    same = [variance_components(_table(part_sd=0.0, scene_sd=3.0, noise_sd=1.0, seed=s)[0])["parts_differ_p"]
            for s in range(200)]
    assert 0.01 <= np.mean(np.asarray(same) < 0.05) <= 0.10  # about 5 % false alarms
    differ = variance_components(_table(parts=24, part_sd=1.0, scene_sd=3.0, noise_sd=1.0, seed=int(rng.integers(99)))[0])
    assert differ["parts_differ_p"] < 1e-6


def test_a_few_scenes_interval_stays_within_what_the_metric_can_take():
    """Two scenes give the t interval of the mean under one degree of freedom: a depth MAE's reached below 0 m
    (a report printed −1.397–2.035 m). It is cut at the metric's span (``Metric.span``)."""
    from doefab.tolerance.delivered import mean_interval

    rng = np.random.default_rng(3)
    rows = [[0.05 + rng.normal(0, 0.01), 0.60 + rng.normal(0, 0.01)] for _ in range(6)]
    samples = [{"network_scenes": {"nominal_psf": {"mae": r, "delta125": [0.9, 0.6]}}} for r in rows]
    got = delivered_summary(samples, {"nominal_psf": {"mae": [0.05, 0.6], "delta125": [0.9, 0.6]}}, {}, "depth")
    d = got["nominal_psf"]
    assert d["metric"] == "mae"
    assert mean_interval(d["mean"], d["components"])[0] < 0  # what the t interval alone gives
    assert d["mean_ci95"][0] == 0.0 and d["mean_ci95"][1] > d["mean"]


def test_a_relative_spec_is_said_as_what_it_is_relative_to():
    """The report printed "≥ 28.35 dB" and "≥ 28.36 dB" for one spec, 1 dB below each label's error-free part,
    without saying so; an absolute limit stays a bare number."""
    from doefab.tolerance.reporttext import spec_words

    res = {"task": "hdr", "budget": {"spec": {"hdr": {"psnr_highlight_db_loss_max": 1.0, "psf_metric_min": 0.8}}},
           "nominal": {"psf": {"psf_metric": 0.87}, "network": {"nominal_psf": {"psnr_highlight": 29.35}}}}
    assert spec_words(res, "network") == "highlight PSNR ≥ 28.35 dB (1.00 dB below the error-free part's 29.35 dB)"
    assert spec_words(res, "psf") == "PSF metric ≥ 0.800"
    res["budget"]["spec"]["hdr"] = {"psf_metric_loss_max": 0.05}  # relative at the PSF level too: 0.87 − 0.05
    assert spec_words(res, "psf") == "PSF metric ≥ 0.820 (0.050 below the error-free part's 0.870)"


def test_a_change_that_rounds_to_zero_has_no_minus_sign():
    from doefab.tolerance.reporttext import signed_change

    assert signed_change(-4e-6) == "+0.0000" and signed_change(-0.0123) == "-0.0123" and signed_change(0.5) == "+0.5000"
