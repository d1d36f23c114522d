"""Tolerance studies: one-at-a-time sweeps with a tornado ranking, Monte Carlo with confidence intervals and
yield, and a quantization study — in process, in a local process pool, or on a Dask cluster.

Sample i of a Monte Carlo run draws its errors from ``SeedSequence(seed).spawn(n)[i]``, so the numbers are the
same bit for bit whatever the number of workers or the backend. Finished samples are appended to
``samples.jsonl`` as they arrive, so an interrupted study resumes where it stopped; a lost Dask worker's
samples are recomputed by Dask (futures are retried), never lost.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors, budget_value, nominal_gap, sample_errors

__all__ = ["SWEEPS", "sweep", "monte_carlo", "summarize", "quantization_study", "budget_errors"]

_JUDGES: dict = {}


def _judge(design_dir: str, supersample: int):
    """One judge per (design, supersample) per process: workers rebuild it from the design folder."""
    key = (str(design_dir), int(supersample))
    if key not in _JUDGES:
        import torch

        from doefab.tolerance.judge import PSFJudge

        torch.set_num_threads(1 if os.environ.get("DOEFAB_WORKER") else max(1, torch.get_num_threads()))
        _JUDGES[key] = PSFJudge(design_dir, supersample)
    return _JUDGES[key]


def _evaluate(design_dir: str, supersample: int, errors: dict, networks: bool = False) -> dict:
    err = PartErrors(**errors)
    res = _judge(design_dir, supersample).evaluate(err)
    if networks:
        res["network"] = _network_judge(design_dir, supersample).evaluate(err)
    return res


_NET_JUDGES: dict = {}


def _network_judge(design_dir: str, supersample: int):
    key = (str(design_dir), int(supersample))
    if key not in _NET_JUDGES:
        from doefab.tolerance.netjudge import NetworkJudge

        _NET_JUDGES[key] = NetworkJudge(_judge(design_dir, supersample))
    return _NET_JUDGES[key]


# one-at-a-time sweeps: name -> (unit for the axis, magnitudes in that unit, builder(magnitude in SI) -> PartErrors)
def _ov(v):
    return replace(PartErrors(), overlay=((0.0, 0.0), (v, 0.0), (0.0, v), (v, -v)))


SWEEPS = {
    "etch depth (systematic)": ("%", [-10, -5, -2, 2, 5, 10], 0.01,
                                lambda v: replace(PartErrors(), depth_scale=(1 + v,) * 4)),
    "mask overlay": ("µm", [0.1, 0.5, 1, 2, 3], 1e-6, _ov),
    "mask rotation": ("µrad", [10, 30, 100], 1e-6,
                      lambda v: replace(PartErrors(), rotation=(0.0, v, -v, v))),
    "edge bias": ("µm", [-1, -0.5, -0.1, 0.1, 0.5, 1], 1e-6, lambda v: replace(PartErrors(), edge_bias=v)),
    "surface roughness": ("nm rms", [5, 10, 20], 1e-9, lambda v: replace(PartErrors(), roughness=v)),
    "decenter across split": ("mm", [0.05, 0.1, 0.25], 1e-3, lambda v: replace(PartErrors(), mount_shift=(v, 0.0))),
    "decenter along split": ("mm", [0.05, 0.1, 0.25], 1e-3, lambda v: replace(PartErrors(), mount_shift=(0.0, v))),
    "mount rotation": ("°", [0.25, 0.5, 1.0, 2.4], math.pi / 180, lambda v: replace(PartErrors(), mount_rotation=v)),
    "axial gap": ("mm", [0.5, 1, 2, 5, 10], 1e-3, lambda v: replace(PartErrors(), axial_gap=v)),
    "crosstalk, uncalibrated": ("%", [2, 5, 10], 0.01,
                                lambda v: replace(PartErrors(), crosstalk=(v, v), calibrated=False)),
    "crosstalk, calibrated": ("%", [2, 5, 10], 0.01, lambda v: replace(PartErrors(), crosstalk=(v, v), calibrated=True)),
}


def budget_errors(budget: dict) -> dict:
    """Each error at its budget value (1 sigma or the bound), for the tornado chart."""
    g = partial(budget_value, budget)
    e = g("etch", "systematic_sigma_percent") + g("etch", "random_sigma_percent")
    return {
        "etch depth (systematic)": replace(PartErrors(), depth_scale=(1 + e / 100,) * 4),
        "mask overlay": _ov(g("overlay", "shift_sigma_um") * 1e-6),
        "mask rotation": replace(PartErrors(), rotation=(0.0,) + (g("overlay", "rotation_sigma_urad") * 1e-6,) * 3),
        "edge bias": replace(PartErrors(), edge_bias=g("lithography", "edge_bias_sigma_um") * 1e-6),
        "surface roughness": replace(PartErrors(), roughness=g("surface", "roughness_rms_nm") * 1e-9),
        "decenter across split": replace(PartErrors(), mount_shift=(g("mounting", "decenter_max_mm") * 1e-3, 0.0)),
        "decenter along split": replace(PartErrors(), mount_shift=(0.0, g("mounting", "decenter_max_mm") * 1e-3)),
        "mount rotation": replace(PartErrors(), mount_rotation=math.radians(g("mounting", "rotation_sigma_deg"))),
        "axial gap": replace(PartErrors(), axial_gap=nominal_gap(budget) + g("mounting", "axial_gap_sigma_mm") * 1e-3),
        "crosstalk, uncalibrated": replace(PartErrors(), crosstalk=(g("sensor", "crosstalk_lr_percent") / 100,
                                                                    g("sensor", "crosstalk_rl_percent") / 100),
                                           calibrated=False),
    }


def sweep(design_dir, supersample: int = 1, names=None, progress: bool = True) -> dict:
    """Each metric against each error's magnitude (one error at a time)."""
    judge = _judge(str(design_dir), supersample)
    nominal = judge.score(judge.nominal)
    out = {"nominal": nominal, "sweeps": {}}
    items = [(n, SWEEPS[n]) for n in (names or SWEEPS)]
    bar = _bar(sum(len(v[1]) for _, v in items), "sweeps", progress)
    for name, (unit, mags, si, build) in items:
        rows = []
        for m in mags:
            r = judge.evaluate(build(m * si))
            rows.append({"magnitude": m, **r})
            if bar is not None:
                bar.update(1)
                bar.set_postfix(error=name[:18], metric=f"{r['metric']:.3f}")
        out["sweeps"][name] = {"unit": unit, "rows": rows}
    if bar is not None:
        bar.close()
    return out


def tornado(design_dir, budget: dict, supersample: int = 1) -> list[dict]:
    """Metric change caused by each error alone at its budget value, largest first."""
    judge = _judge(str(design_dir), supersample)
    nominal = judge.score(judge.nominal)["metric"]
    rows = [{"error": n, "metric": judge.evaluate(e)["metric"]} for n, e in budget_errors(budget).items()]
    for r in rows:
        r["delta"] = r["metric"] - nominal
    return sorted(rows, key=lambda r: -abs(r["delta"]))


def _bar(total, desc, progress):
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="sample")


def monte_carlo(design_dir, budget: dict, n: int, out_dir: str | Path, seed: int = 0, supersample: int = 1,
                scheduler: str | None = None, workers: int = 1, progress: bool = True,
                networks: bool = False) -> list[dict]:
    """``n`` sampled parts; returns every sample's errors and metrics (ordered by index).

    scheduler: None (in process, or a local process pool of ``workers``), ``"local:N"`` (a Dask
    ``LocalCluster`` of N workers) or ``"tcp://HOST:PORT"`` (an existing Dask scheduler).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "samples.jsonl"
    done = {}
    if log.is_file():
        for line in log.read_text().splitlines():
            try:
                r = json.loads(line)
                done[int(r["index"])] = r
            except (ValueError, KeyError):
                continue  # a line cut by an interruption: recomputed
    children = np.random.SeedSequence(seed).spawn(n)
    todo = [i for i in range(n) if i not in done]
    errs = {i: sample_errors(budget, np.random.default_rng(children[i]), seed=int(children[i].generate_state(1)[0]))
            for i in todo}
    spec = float(budget.get("spec", {}).get("metric_min", 0.0))
    bar = _bar(n, "Monte Carlo", progress)
    if bar is not None:
        bar.update(len(done))
    t0 = time.perf_counter()

    def record(i, res):
        row = {"index": i, "errors": errs[i].to_json(), **res, "seconds": round(time.perf_counter() - t0, 3)}
        done[i] = row
        with open(log, "a") as fh:
            fh.write(json.dumps(row) + "\n")
        if bar is not None:
            ok = np.mean([r["metric"] >= spec for r in done.values()])
            bar.update(1)
            bar.set_postfix(metric=f"{res['metric']:.3f}", running_yield=f"{ok:.2f}")

    ddir = str(design_dir)
    try:
        if scheduler:
            _run_dask(scheduler, ddir, supersample, todo, errs, record, networks)
        elif workers > 1:
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(workers, initializer=_worker_init) as ex:
                futs = {ex.submit(_evaluate, ddir, supersample, errs[i].to_json(), networks): i for i in todo}
                for f in as_completed(futs):
                    record(futs[f], f.result())
        else:
            for i in todo:
                record(i, _evaluate(ddir, supersample, errs[i].to_json(), networks))
    finally:
        if bar is not None:
            bar.close()
    return [done[i] for i in range(n)]


def _worker_init():
    os.environ["DOEFAB_WORKER"] = "1"
    import torch

    torch.set_num_threads(1)


def _run_dask(scheduler, ddir, supersample, todo, errs, record, networks=False):
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise DoefabError("--scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
    cluster = None
    if scheduler.startswith("local:"):
        try:
            nw = int(scheduler.split(":", 1)[1])
        except ValueError:
            raise DoefabError(f"--scheduler local:N needs a worker count, got {scheduler!r}") from None
        cluster = LocalCluster(n_workers=nw, threads_per_worker=1, processes=True, dashboard_address=None,
                               env={"DOEFAB_WORKER": "1", "OMP_NUM_THREADS": "1"})
        client = Client(cluster)
    elif scheduler.startswith("tcp://"):
        client = Client(scheduler)
    else:
        raise DoefabError(f"--scheduler must be local:N or tcp://HOST:PORT, got {scheduler!r}")
    try:
        futs = {client.submit(_evaluate, ddir, supersample, errs[i].to_json(), networks, key=f"doefab-sample-{i}",
                              retries=2, pure=False): i for i in todo}
        for f in as_completed(futs):
            record(futs[f], f.result())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def summarize(samples: list[dict], spec: float) -> dict:
    """Mean, 95 % interval of the mean (normal approximation) and yield (Wilson interval) of each metric."""
    out = {}
    for key in ("metric", "worst", "l1_to_nominal"):
        v = np.array([s[key] for s in samples], float)
        half = 1.96 * v.std(ddof=1) / math.sqrt(len(v)) if len(v) > 1 else float("nan")
        out[key] = {"mean": float(v.mean()), "ci95": [float(v.mean() - half), float(v.mean() + half)],
                    "ci95_width": float(2 * half)}
    ok = np.array([s["metric"] >= spec for s in samples])
    n, p = len(ok), float(ok.mean())
    z = 1.96
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    w = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    out["yield"] = {"spec_metric_min": spec, "value": p, "ci95": [max(0.0, centre - w), min(1.0, centre + w)]}
    return out


def quantization_study(design_dir, levels=(None, 16, 8, 4, 2), supersample: int = 1,
                       networks: bool = False) -> list[dict]:
    """The same design at continuous (None) and N-level quantization, on the PSF metric (and, with
    ``networks``, through the shipped network given the nominal and the quantized design's PSF)."""
    from doefab.fabrication.levels import quantize_levels

    judge = _judge(str(design_dir), supersample)
    d = judge.design
    rows = []
    height = continuous_height(d)
    for n in levels:
        if n is None and height is None:
            rows.append({"levels": "continuous", "metric": float("nan"), "worst": float("nan"),
                         "l1_to_nominal": float("nan"),
                         "note": "n/a: the design folder keeps only the 16-level map (no height.npy)"})
            continue
        h2pi = d.camera.material.height_2pi(d.camera.design_wavelength)
        if n is None:
            h = np.mod(height, h2pi)
        else:
            lv = quantize_levels(d.height if height is None else height, d.camera, n)
            h = lv.astype(np.float64) * h2pi / n
        if supersample > 1:
            h = np.kron(h, np.ones((supersample, supersample)))
        row = {"levels": "continuous" if n is None else n, **judge.score(judge.psf_from_height(h))}
        if networks:
            row["network"] = _network_judge(str(design_dir), supersample).evaluate(PartErrors(), height=h)
        rows.append(row)
    return rows


def continuous_height(design):
    """The design's continuous (unquantized) heights in metres, or None when the folder keeps only its 16-level map:
    from ``height.npy``, or rebuilt from a radial design's knots (``extra.radial_knots_waves``)."""
    import torch

    from doefab.design.optimize import PLAIN_LEVEL, _coded_mask
    from doefab.design.parameterization import RadialParam, theta_to_height
    from doefab.fabrication.levels import level_step, levels_to_height

    d = design
    if not np.allclose(d.height, levels_to_height(d.levels, d.camera), rtol=0, atol=1e-12):
        return d.height
    knots = d.extra.get("radial_knots_waves")
    if not knots:
        return None
    with torch.no_grad():
        h = theta_to_height(RadialParam(d.camera, len(knots)).waves(torch.tensor(knots, dtype=torch.float64)),
                            d.camera).numpy()
    mask = _coded_mask(d.camera).numpy() > 0
    return np.where(mask, h, PLAIN_LEVEL * level_step(d.camera))
