"""What the parts deliver through the network, with the noise of the scenes they were judged on.

Every part is judged on the same scenes (``netjudge``), so a part's delivered value — the mean over those scenes —
carries two kinds of scene noise besides the part-to-part spread it is meant to show: the scene set's difficulty,
common to every part (and to the error-free part a relative spec is measured from), and the part × scene
interaction, each part's own. ``variance_components`` separates the three (a two-way analysis of variance without
replication); ``bootstrap`` resamples the parts and then the scenes — one draw of scenes for all the parts of a
replicate, since they share them — so an interval of the mean or of the yield holds both sources of noise.
``delivered_summary`` gives both for each PSF the network was told. One error alone against the error-free part
(the tornado) is judged on the same scenes too: ``change_noise`` gives the half-width of its change's 95 % interval
from the paired per-scene changes, the scene noise a single part's change carries.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

__all__ = ["variance_components", "crossed_mean_stats", "mean_interval", "bootstrap", "delivered_summary", "scene_table", "change_noise",
           "BOOT_DRAWS"]

BOOT_DRAWS = 2000  # bootstrap replicates: the 2.5 % and 97.5 % quantiles move by well under their width's 1 %


def variance_components(x) -> dict:
    """Variance components of one metric on a [parts, scenes] table (every part on the same scenes; a scene
    where the metric is nan for some part, e.g. a highlight metric without highlights, is left out):

    ``part_sd``: spread of the parts' values over infinitely many scenes; ``scene_sd``: spread of the scenes'
    difficulty; ``interaction_sd``: a part's own scene-to-scene noise; ``part_noise_sd`` = interaction_sd / √scenes,
    the scene noise on a part's value relative to the other parts' (what blurs which parts pass);
    ``common_noise_sd`` = scene_sd / √scenes, the scene set's offset shared by every part; ``scenes_needed``: the
    fewest scenes that put part_noise_sd below part_sd (None when part_sd is 0), a point estimate;
    ``parts_differ_p``: the F test's p-value that the parts differ at all (mean square of the parts against the
    interaction's: above 0.05 these scenes do not resolve a part-to-part spread, and ``scenes_needed`` has no upper
    bound); ``mean_se``, ``mean_df``: standard error of the grand mean over parts and scenes — parts and scenes both
    random, crossed — ``√((MS_parts + MS_scenes − MS_interaction) / (parts·scenes))``, and its Satterthwaite degrees
    of freedom (:func:`mean_interval`). Needs two parts and two scenes (else the values are nan)."""
    x = np.asarray(x, np.float64)
    x = x[:, np.all(np.isfinite(x), axis=0)] if x.ndim == 2 else np.empty((0, 0))
    p, s = x.shape if x.size else (0, 0)
    out = {"parts": int(p), "scenes": int(s)}
    if p < 2 or s < 2:
        nan = float("nan")
        return {**out, "part_sd": nan, "scene_sd": nan, "interaction_sd": nan, "part_noise_sd": nan,
                "common_noise_sd": nan, "scenes_needed": None, "parts_differ_p": nan, "mean_se": nan, "mean_df": nan}
    grand, rows, cols = x.mean(), x.mean(axis=1), x.mean(axis=0)
    ms_part = s * np.sum((rows - grand) ** 2) / (p - 1)
    ms_scene = p * np.sum((cols - grand) ** 2) / (s - 1)
    ms_rest = np.sum((x - rows[:, None] - cols[None, :] + grand) ** 2) / ((p - 1) * (s - 1))
    v_part, v_scene = max(0.0, (ms_part - ms_rest) / s), max(0.0, (ms_scene - ms_rest) / p)
    return {**out, "part_sd": math.sqrt(v_part), "scene_sd": math.sqrt(v_scene), "interaction_sd": math.sqrt(ms_rest),
            "part_noise_sd": math.sqrt(ms_rest / s), "common_noise_sd": math.sqrt(v_scene / s),
            "scenes_needed": int(ms_rest // v_part) + 1 if v_part > 0 else None,
            **crossed_mean_stats(ms_part, ms_scene, ms_rest, p, s)}


def crossed_mean_stats(ms_part: float, ms_scene: float, ms_rest: float, parts: int, scenes: int) -> dict:
    """{"parts_differ_p", "mean_se", "mean_df"} of a parts × scenes table from its three mean squares (parts,
    scenes, interaction; :func:`variance_components`): the parts' F test, and the grand mean's standard error with
    parts and scenes both random — its variance σ²_p/parts + σ²_s/scenes + σ²_e/(parts·scenes) is
    (MS_p + MS_s − MS_e)/(parts·scenes), never below the interaction's own share MS_e/(parts·scenes) — with
    Satterthwaite's degrees of freedom (the interaction's where the floor holds).

    Example: ``crossed_mean_stats(4.2, 40.0, 1.1, 24, 8)["mean_se"]`` (the metric's unit)."""
    df_rest = (parts - 1) * (scenes - 1)
    combo = ms_part + ms_scene - ms_rest
    den = ms_part ** 2 / (parts - 1) + ms_scene ** 2 / (scenes - 1) + ms_rest ** 2 / df_rest
    return {"parts_differ_p": _f_test(ms_part, ms_rest, parts - 1, df_rest),
            "mean_se": math.sqrt(max(combo, ms_rest, 0.0) / (parts * scenes)),
            "mean_df": combo ** 2 / den if combo > ms_rest and den > 0 else float(df_rest)}


def _f_test(ms_part: float, ms_rest: float, df_part: int, df_rest: int) -> float:
    """p-value of the parts' F ratio (1 when neither mean square varies: nothing to tell apart)."""
    from scipy.stats import f

    if ms_rest <= 0:
        return 0.0 if ms_part > 0 else 1.0
    return float(f.sf(ms_part / ms_rest, df_part, df_rest))


def mean_interval(mean: float, components: dict) -> list[float]:
    """95 % interval of the parts' mean delivered value over parts and scenes, both random and crossed: ``mean`` ±
    Student's t at ``components``' Satterthwaite ``mean_df`` times its ``mean_se`` (:func:`variance_components`).
    A percentile bootstrap over a few scenes reads narrow (with 8 scenes its scene variance is 7/8 of the unbiased
    one, and its percentiles are normal ones where t's 7 degrees of freedom hold): this interval does not.
    [nan, nan] without two parts and two scenes.

    Example: ``mean_interval(28.7, variance_components(x))`` with ``x`` [parts, scenes] highlight PSNRs (dB)."""
    from scipy.stats import t

    se, df = components["mean_se"], components["mean_df"]
    if not (math.isfinite(se) and df > 0):
        return [float("nan"), float("nan")]
    half = float(t.ppf(0.975, df)) * se
    return [mean - half, mean + half]


def bootstrap(x, passes=None, nominal=None, primary: int = 0, draws: int = BOOT_DRAWS, seed: int = 0,
              scenes: bool = True) -> dict:
    """Two-level bootstrap of the parts' mean delivered value and yield.

    ``x``: [parts, scenes, metrics] values (every part on the same scenes); ``nominal``: the error-free part's
    [scenes, metrics] values (a relative spec's reference) or None; ``passes(part_means [parts, metrics],
    nominal_means [metrics] or None) → bool [parts]``: which parts meet the spec (None: no yield). Each replicate
    draws the parts with replacement and then, with ``scenes``, the scenes with replacement (one draw for every
    part and the error-free one), each part's value being its mean over the drawn scenes. Without ``scenes`` it
    is the part-level bootstrap, and with the same ``seed`` it draws the same parts. Returns {"mean",
    "mean_ci95", "yield", "yield_ci95", "draws", "scenes_resampled"}: the point values from all parts and
    scenes, the intervals the 2.5–97.5 % percentiles over the replicates (``primary``: the metric whose mean)."""
    x = np.asarray(x, np.float64)
    n_parts, n_scenes = x.shape[:2]
    nom = None if nominal is None else np.asarray(nominal, np.float64)
    rng_parts = np.random.default_rng(np.random.SeedSequence([seed, 0]))
    rng_scenes = np.random.default_rng(np.random.SeedSequence([seed, 1]))
    parts = rng_parts.integers(n_parts, size=(draws, n_parts))
    drawn = (rng_scenes.integers(n_scenes, size=(draws, n_scenes)) if scenes
             else np.broadcast_to(np.arange(n_scenes), (draws, n_scenes)))
    point = _stats(x, nom, passes, primary, np.arange(n_parts)[None], np.arange(n_scenes)[None])
    chunk = max(1, 2**22 // max(1, x.size))  # replicates at a time: a few tens of MB of drawn values
    reps = np.concatenate([_stats(x, nom, passes, primary, parts[i:i + chunk], drawn[i:i + chunk])
                           for i in range(0, draws, chunk)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, hi = np.nanpercentile(reps, [2.5, 97.5], axis=0)
    return {"mean": float(point[0, 0]), "mean_ci95": [float(lo[0]), float(hi[0])],
            "yield": float(point[0, 1]) if passes else None,
            "yield_ci95": [float(lo[1]), float(hi[1])] if passes else None, "draws": int(draws),
            "scenes_resampled": bool(scenes)}


def _stats(x, nom, passes, primary, parts, drawn) -> np.ndarray:
    """[replicates, 2] (mean of the primary metric over the parts, yield) of replicates that take parts
    ``parts[r]`` and scenes ``drawn[r]``."""
    with warnings.catch_warnings():  # a metric no drawn scene defines: nan, as ``mean_metrics`` gives
        warnings.simplefilter("ignore", RuntimeWarning)
        means = np.nanmean(x[parts[:, :, None], drawn[:, None, :]], axis=2)  # [r, parts, metrics]
        refs = None if nom is None else np.nanmean(nom[drawn], axis=1)  # [r, metrics]
        mean = np.nanmean(means[:, :, primary], axis=1)
    if passes is None:
        return np.stack([mean, np.full_like(mean, np.nan)], axis=1)
    y = [np.mean(passes(m, None if refs is None else refs[r])) for r, m in enumerate(means)]
    return np.stack([mean, np.asarray(y, np.float64)], axis=1)


def scene_table(samples: list[dict], label: str) -> tuple[list[str], np.ndarray]:
    """(metric names, [parts, scenes, metrics] values) of the parts the network judged, told ``label``'s PSF."""
    per = [s["network_scenes"][label] for s in samples]
    names = list(per[0])
    return names, np.array([[m[k] for k in names] for m in per], np.float64).transpose(0, 2, 1)


def delivered_summary(samples: list[dict], nominal_scenes: dict, spec: dict, task: str, seed: int = 0) -> dict:
    """{label: {"metric", "mean", "mean_ci95", "yield", "yield_ci95", "bootstrap_yield_ci95", "wilson_ci95",
    "components", "draws"}} for each PSF the network was told: the task's primary delivered metric, its mean
    over the parts and the yield against ``spec`` (relative limits against the error-free part on the same
    scenes, ``nominal_scenes[label]``: {metric: [value per scene]}), and its variance components. ``mean_ci95`` is
    the crossed design's t interval (:func:`mean_interval`; the two-level bootstrap's where the scenes define no
    components), within the values the metric can take (``Metric.span``: with two scenes a depth MAE's t interval
    reached below 0 m), ``bootstrap_mean_ci95`` the bootstrap's beside it. ``yield_ci95`` is the hull of the two-level
    bootstrap's and the parts' Wilson interval: resampled parts cannot fail when every part passed, Wilson's stays
    honest there; with a few scenes the bootstrap's scene share reads narrow (:func:`mean_interval`). Empty without
    per-scene values."""
    from doefab.tolerance.yieldstats import wilson
    from doefab.tolerance.spec import PRIMARY, SPAN, spec_limits

    if not samples or "network_scenes" not in samples[0] or task not in PRIMARY:
        return {}
    out = {}
    for label in samples[0]["network_scenes"]:
        names, x = scene_table(samples, label)
        nom = np.array([nominal_scenes[label][k] for k in names], np.float64).T
        primary = names.index(PRIMARY[task])

        def passes(means, nominal_means):  # ``spec.meets`` of every part at once
            ok = np.ones(len(means), bool)
            for _, metric, limit, op in spec_limits(spec, task, "network", dict(zip(names, nominal_means))):
                v = means[:, names.index(metric)] if metric in names else np.full(len(means), np.nan)
                with np.errstate(invalid="ignore"):
                    ok &= np.isfinite(v) & (v >= limit if op == "≥" else v <= limit)
            return ok
        b = bootstrap(x, passes, nom, primary, seed=seed)
        k = int(round(b["yield"] * len(samples)))
        w = wilson(k, len(samples))
        comps = variance_components(x[:, :, primary])
        t_ci = mean_interval(b["mean"], comps)
        lo, hi = SPAN[task].get(PRIMARY[task], (-math.inf, math.inf))  # a few scenes' t reaches past what it can be
        out[label] = {"metric": PRIMARY[task], "mean": b["mean"],
                      "mean_ci95": [max(t_ci[0], lo), min(t_ci[1], hi)] if math.isfinite(t_ci[0]) else b["mean_ci95"],
                      "bootstrap_mean_ci95": b["mean_ci95"], "yield": b["yield"],
                      "yield_ci95": [min(w[0], b["yield_ci95"][0]), max(w[1], b["yield_ci95"][1])],
                      "bootstrap_yield_ci95": b["yield_ci95"], "wilson_ci95": list(w), "draws": b["draws"],
                      "components": comps}
    return out


def change_noise(changes: dict) -> dict:
    """{label: {metric: half-width of the 95 % interval of the change}} of one part against the error-free one
    judged on the same scenes, from the paired per-scene changes ``changes`` ({label: {metric: [part − base on
    each scene]}}, as ``study.tornado_rows`` records them): Student's t with n − 1 degrees of freedom times the
    standard error of the n changes (a scene where either value is nan is left out; None with fewer than two).
    The change of the means is resolved by these scenes only where it exceeds this: the rest is the part × scene
    noise, and for HDR also the highlight solve's sensitivity to rounding where both captures clip.

    Example: ``change_noise({"nominal_psf": {"mae": [0.1, 0.2, 0.1]}})`` → ``{"nominal_psf": {"mae": 0.143...}}``
    (metres)."""
    from scipy.stats import t

    out = {}
    for label, metrics in changes.items():
        out[label] = {}
        for m, vals in metrics.items():
            d = np.asarray(vals, np.float64)
            d = d[np.isfinite(d)]
            n = d.size
            out[label][m] = (float(t.ppf(0.975, n - 1) * d.std(ddof=1) / math.sqrt(n)) if n >= 2 else None)
    return out
