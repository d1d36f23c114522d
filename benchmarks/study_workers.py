"""A tolerance study's network passes outside its Monte Carlo, as the main job runs them: the error-free part
through the network, the tornado (every error kind of the default budget alone at one standard deviation at PSF
level, its five largest through the network) and the quantization study through the network (continuous, 16, 8,
4 and 2 levels), each committed design on grid 1 with the judge's default scenes (``netjudge``: 8 test scenes of
256² px per part), from an empty PSF cache. The previous code (``--baseline REV``) is timed in the same run, each
code in a fresh process, the two taking turns design by design; each row's delivered metrics are compared between
the codes (the largest difference of any metric on any scene).

Writes benchmarks/results/study_workers.{md,json}. Run with nothing else on the machine:
    .venv/bin/python benchmarks/study_workers.py --baseline REV
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

from revisions import ROOT, add_arguments, code_root, measure_at, same_code_warning, turns

DESIGNS = ("streak", "grating", "half-ring")
TOP = 5  # the main job's network_top
JUDGE = {"images": 8, "size": 256, "split": "test"}  # the main job's judge (pipeline.stages.stage_tolerance)


def measure(name: str, threads: int) -> dict:
    """Seconds of each pass and every network-judged row's per-scene metrics, with the package at ``code_root``."""
    os.environ["DOEFAB_CACHE"] = tempfile.mkdtemp(prefix="study_workers_")  # an empty PSF cache
    sys.path.insert(0, code_root())
    import torch

    from doefab.tolerance import study
    from doefab.tolerance.errors import PartErrors, load_budget
    from doefab.tolerance.memory import keep_freed_memory

    torch.set_num_threads(threads)
    keep_freed_memory()
    design = str(ROOT / "masks" / name / "design")
    budget = load_budget()
    out, scenes = {}, {}
    t = time.perf_counter()
    nominal = study.evaluate_part(design, 1, PartErrors().to_json(), JUDGE)
    out["error-free part"] = time.perf_counter() - t
    scenes["error-free part"] = nominal["network_scenes"]
    t = time.perf_counter()
    rows = study.tornado(design, budget, {}, JUDGE, None, False, TOP)
    out["tornado"] = time.perf_counter() - t
    scenes.update({f"tornado: {r['error']}": r["network"] for r in rows if "network" in r})
    t = time.perf_counter()
    quant = study.quantization_study(design, supersample=1, networks=JUDGE, progress=False)
    out["quantization study"] = time.perf_counter() - t
    scenes.update({f"quantization: {r['levels']}": r["network_scenes"] for r in quant if "network_scenes" in r})
    return {"seconds": out, "rows": scenes, "cores": len(os.sched_getaffinity(0))}


def _largest_difference(a: dict, b: dict) -> float:
    """The largest |a − b| over every metric of every label (and scene) two codes' rows share."""
    diff = 0.0
    for lab, metrics in a.items():
        for m, v in metrics.items():
            w = b.get(lab, {}).get(m)
            if w is None:
                continue
            for x, y in zip(v if isinstance(v, list) else [v], w if isinstance(w, list) else [w]):
                if x == x and y == y:  # both defined (NaN where a metric is not)
                    diff = max(diff, abs(x - y))
    return diff


def write(data: dict, out: Path) -> None:
    """study_workers.{json,md} in ``out``."""
    runs = data["designs"]["streak"]
    same_code_warning(runs.get("baseline", {}).get("revision"), runs["this_code"]["revision"])
    md = ["# Network passes outside the Monte Carlo", "",
          f"`.venv/bin/python benchmarks/study_workers.py --baseline {data['baseline_arg']}` ({data['threads']} torch "
          f"threads in the study's process, {runs['this_code']['cores']} cores): the error-free part through the "
          f"network, the tornado (its {TOP} largest errors at PSF level through the network) and the quantization "
          "study through the network, each design on grid 1 with 8 test scenes of 256² px per part, from an empty "
          "PSF cache; the previous code timed in the same run, each code in a fresh process. One timing each.", "",
          "| design | pass | previous code (s) | this code (s) | this / previous | largest difference of a delivered "
          "metric on a scene |", "| --- | --- | --- | --- | --- | --- |"]
    for name, r in data["designs"].items():
        this, prev = r["this_code"], r.get("baseline")
        for step, s in this["seconds"].items():
            p = prev["seconds"][step] if prev else float("nan")
            rows = [k for k in this["rows"] if (step == "error-free part" and k == step)
                    or k.startswith(step.split()[0] + ":")]
            diff = max((_largest_difference(this["rows"][k], prev["rows"].get(k, {})) for k in rows),
                       default=float("nan")) if prev else float("nan")
            md.append(f"| {name} | {step} | {p:.1f} | {s:.1f} | {s / p:.2f} | {diff:.3g} |")
    md += ["", f"Revisions: previous {runs.get('baseline', {}).get('revision', '—')}, this "
               f"{runs['this_code']['revision']}."]
    (out / "study_workers.json").write_text(json.dumps(data, indent=1) + "\n")
    (out / "study_workers.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(ap)
    ap.add_argument("--design", choices=DESIGNS, help=argparse.SUPPRESS)
    ap.add_argument("--designs", default=",".join(DESIGNS), help="comma-separated designs to time")
    a = ap.parse_args()
    if a.measure_only:
        print(json.dumps(measure(a.design, a.threads)))
        return
    data = {"threads": a.threads, "baseline_arg": a.baseline, "designs": {}}
    for i, name in enumerate(a.designs.split(",")):
        for code in turns(a.baseline, start=i):
            rev, res = measure_at(code, __file__, ["--design", name, "--threads", str(a.threads)])
            data["designs"].setdefault(name, {})["this_code" if code is None else "baseline"] = {"revision": rev,
                                                                                                  **res}
            print(name, rev, {k: round(v, 1) for k, v in res["seconds"].items()}, flush=True, file=sys.stderr)
    write(data, Path(a.results))


if __name__ == "__main__":
    main()
