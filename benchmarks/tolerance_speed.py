"""How fast a tolerance study decides, and how far its surrogate's yield lies from the direct Monte Carlo's.

``psf``: ``doefab tolerance --design masks/grating --samples 300`` (PSF level, default budget, grid chosen by the
study, default workers: one process per core); then the same study resumed with ``--surrogate`` (the sensitivity
surrogate, calibrated on parts of its own): its yield, and its difference from the direct judgement on the direct
run's 300 parts, part by part, with a 95 % interval.
``network``: parts per minute through each task's network (``--networks``, 6 parts each; the network judge
renders the reconstruction tables' test scenes, ``doefab.tolerance.netjudge.SPLIT``), with the package as of
git revision ``--baseline REV`` (default HEAD; a temporary worktree) timed in the same run, the two codes taking
turns design by design (``--baseline none``: this code only).
Writes benchmarks/results/tolerance_speed.{md,json}. Run with nothing else on the machine:
    .venv/bin/python benchmarks/tolerance_speed.py psf network --baseline REV
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from revisions import ROOT, revision, turns, worktree  # this folder is on the path of a script run

OUT = Path(__file__).parent / "results"
DOEFAB = [sys.executable, "-m", "doefab"]


def run(args: list[str], out: Path, code: Path = ROOT) -> tuple[dict, float]:
    """``doefab tolerance args --out out`` with the package at ``code`` (run from there: ``-m`` finds it first)."""
    t = time.perf_counter()
    subprocess.run(DOEFAB + ["tolerance", *args, "--out", str(out)], check=True, stdout=subprocess.DEVNULL, cwd=code)
    return json.loads((out / "tolerance.json").read_text()), time.perf_counter() - t


def psf_rows(tmp: Path) -> tuple[list[str], dict]:
    rows = ["| command | parts | wall time (s) | Monte Carlo (s) | parts / minute | yield (95 % interval) |",
            "| --- | --- | --- | --- | --- | --- |"]
    import os

    cores = len(os.sched_getaffinity(0))
    data = {}
    for label, extra in (("default", []),):
        res, wall = run(["--design", "masks/grating", "--samples", "300", *extra], tmp / label.replace(" ", "_"))
        y = res["summary"]["yield"]
        data[label] = {"wall_s": wall, "mc_s": res["monte_carlo_seconds"], "parts_per_minute": res["parts_per_minute"],
                       "yield": y, "grid": res["grid"]["monte_carlo_grid"]}
        rows.append(f"| doefab tolerance --design masks/grating --samples 300 {' '.join(extra)} | 300 | {wall:.0f} | "
                    f"{res['monte_carlo_seconds']:.0f} | {res['parts_per_minute']:.1f} | {y['value']:.3f} "
                    f"({y['ci95'][0]:.3f}–{y['ci95'][1]:.3f}) |")
        print(rows[-1], flush=True)
    # the same study resumed (its 300 parts reused) with the surrogate, which is validated on those parts, paired
    res, wall = run(["--design", "masks/grating", "--samples", "300", "--surrogate", "--resume"], tmp / "default")
    s = res["surrogate"]
    data["surrogate"] = {"wall_s": wall, **s}
    c, v, y = s["model"]["calibration"], s["validation"], s["yield"]
    rows.append(f"| doefab tolerance --design masks/grating --samples 300 --surrogate --resume (the parts above reused) "
                f"| {s['model']['parts']} fitted + {c['n']} calibration | {wall:.0f} | — | — | {y['value']:.3f} "
                f"({y['ci95'][0]:.3f}–{y['ci95'][1]:.3f}) |")
    rows += ["", f"Surrogate (metric = {c['alpha']:.4f} + {c['beta']:.3f} × model after calibration), checked part by "
                 f"part on the direct run's {v['n']} parts, which it never saw: surrogate − direct yield "
                 f"{v['yield_difference']:+.3f} (95 % interval {v['yield_difference_ci95'][0]:+.3f} to "
                 f"{v['yield_difference_ci95'][1]:+.3f}), PSF metric {v['metric_difference']:+.4f} "
                 f"({v['metric_difference_ci95'][0]:+.4f} to {v['metric_difference_ci95'][1]:+.4f}), RMSE "
                 f"{v['rmse']:.4f}{'' if v['consistent'] else ': the surrogate is BIASED on them'}."]
    data["cores"] = cores
    return rows, data


def network_rows(tmp: Path, baseline: str) -> tuple[list[str], dict]:
    data = {}
    for i, name in enumerate(("streak", "grating", "half-ring")):
        for code in turns(baseline, start=i):  # the codes take turns, in alternating order
            with worktree(code) as tree:
                sha = revision(tree)
                res, _ = run(["--design", str(ROOT / "masks" / name), "--samples", "6", "--networks", "--grid",
                              "1"], tmp / f"{name}_{code is None}", tree)
            data.setdefault(name, {})["this_code" if code is None else "baseline"] = {
                "revision": sha, "mc_s": res["monte_carlo_seconds"], "parts_per_minute": res["parts_per_minute"]}
            print(name, sha, res["parts_per_minute"], flush=True)
    return network_table(data), data


def network_table(data: dict) -> list[str]:
    """Rows of the network part, the previous code above this code, design by design."""
    rows = ["| design | code | parts through the network | Monte Carlo (s) | parts / minute |",
            "| --- | --- | --- | --- | --- |"]
    for name, runs in data.items():
        for key, label in (("baseline", "previous code"), ("this_code", "this code")):
            if key in runs:
                r = runs[key]
                rows.append(f"| {name} | {label} ({r['revision']}) | 6 | {r['mc_s']:.0f} | "
                            f"{r['parts_per_minute']:.2f} |")
    return rows


def main(parts: list[str], baseline: str = "HEAD"):
    OUT.mkdir(parents=True, exist_ok=True)
    old = OUT / "tolerance_speed.json"
    data = json.loads(old.read_text()) if old.is_file() else {}
    text = {}
    with tempfile.TemporaryDirectory() as tmp:
        for part, fn in (("psf", psf_rows), ("network", lambda t: network_rows(t, baseline))):
            if part in parts:
                rows, data[part] = fn(Path(tmp))
                data.pop(part + "_note", None)  # a note on older rows no longer applies
                if "cores" in data[part]:
                    data["cores"] = data[part]["cores"]
                data[part + "_rows"] = rows
    for part in ("psf", "network"):
        text[part] = data.get(part + "_rows", [])
    old.write_text(json.dumps(data, indent=1) + "\n")
    md = ["PSF level, committed grating design, default budget, on a machine with "
          f"{data.get('cores', '?')} cores (`.venv/bin/python benchmarks/tolerance_speed.py psf`):",
          "", *text["psf"], *(["", data["psf_note"]] if data.get("psf_note") else []), "",
          "Through the networks (`... tolerance_speed.py network --baseline REV`; the previous code timed in the "
          "same run, the two taking turns):", "", *text["network"]]
    (OUT / "tolerance_speed.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("parts", nargs="*", choices=["psf", "network"], default=["psf", "network"])
    ap.add_argument("--baseline", default="HEAD", help="git revision timed beside this code ('none': skip)")
    a = ap.parse_args()
    main(a.parts, a.baseline)
