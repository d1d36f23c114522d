"""How much of a network-judged part's score is rounding: one part drawn from the default budget, judged through
each committed design's proposed network as ``doefab tolerance --networks`` judges it (``study.evaluate_part``:
the judge's default scenes, each reconstructed with the nominal PSF and with the part's own pair), twice, each
time in a fresh process: everything but the reconstructions on two threads (torch, OpenMP, MKL; as the tornado
and the quantization study compute in the study's own process on a 2-core machine) and then on one (as a Monte
Carlo worker does). The reconstructions run on one torch thread both times, so the two differ only in the
rounding of what is computed before them (the part's PSFs, its captures). Per metric: the largest change on any
scene and the change of the mean over the scenes, beside the paired 95 % interval of a tornado row's change
that the report prints (``delivered.change_noise``, here of the rounding change alone).

Writes benchmarks/results/judge_rounding.{md,json}. Run with nothing else on the machine:
    .venv/bin/python benchmarks/judge_rounding.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = Path(__file__).parent / "results"
DESIGNS = ("streak", "grating", "half-ring")
PART_SEED = 1  # the part judge_profile.py times after its warm-up


def judge_once(name: str, threads: int, path: str) -> None:
    """One drawn part of design ``name`` judged with its PSFs on ``threads`` torch threads; its result to ``path``."""
    import numpy as np
    import torch

    if threads == 1:
        os.environ["DOEFAB_WORKER"] = "1"  # as a Monte Carlo worker: one thread for everything
    torch.set_num_threads(threads)
    from doefab.tolerance import study
    from doefab.tolerance.errors import load_budget, sample_errors

    design = str(ROOT / "masks" / name / "design")
    n_masks = study.judge_for(design, 1).n_masks
    err = sample_errors(load_budget(), np.random.default_rng(PART_SEED), seed=PART_SEED, n_masks=n_masks)
    r = study.evaluate_part(design, 1, err.to_json(), networks=True)
    Path(path).write_text(json.dumps({"psf_metric": r["metric"], "scenes": r["network_scenes"],
                                      "threads": torch.get_num_threads()}))


def compare(name: str) -> dict:
    """Both judgements of the part (each in a fresh process) and their differences per label and metric."""
    import numpy as np

    from doefab.applications import of_design
    from doefab.tolerance.delivered import change_noise

    got = {}
    with tempfile.TemporaryDirectory() as tmp:
        for threads in (2, 1):
            path = str(Path(tmp) / f"{threads}.json")
            env = {**os.environ, "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
            subprocess.run([sys.executable, __file__, "--one", name, str(threads), path], check=True, env=env)
            got[threads] = json.loads(Path(path).read_text())
    changes = {lab: {m: list(np.asarray(v, float) - np.asarray(got[2]["scenes"][lab][m], float))
                     for m, v in ms.items()} for lab, ms in got[1]["scenes"].items()}
    noise = change_noise(changes)
    rows = []
    for lab, ms in changes.items():
        for m, d in ms.items():
            d = np.asarray(d)
            fin = d[np.isfinite(d)]
            rows.append({"label": lab, "metric": m, "max_scene_change": float(np.abs(fin).max()) if fin.size else None,
                         "mean_change": float(fin.mean()) if fin.size else None, "scenes": int(fin.size),
                         "ci95_half_width": noise[lab][m]})
    return {"design": name, "task": of_design(name).name, "psf_metric_change": got[1]["psf_metric"] - got[2]["psf_metric"],
            "threads": [got[2]["threads"], got[1]["threads"]], "rows": rows}


def markdown(runs: list[dict], code: str) -> str:
    from doefab.reconstruction.metrics import DISPLAY

    lines = ["# The network judge's rounding", "",
             f"Produced by `.venv/bin/python benchmarks/judge_rounding.py` at {code}: one part drawn from the default "
             f"budget (seed {PART_SEED}) judged through each committed design's proposed network on the judge's "
             "scenes, everything but the reconstructions on 2 threads and then on 1 (torch, OpenMP and MKL; each in a "
             "fresh process; the reconstructions on 1 torch thread both times). What the second judgement changes:",
             "",
             "| design | network told | metric | largest change on a scene | change of the mean over the scenes | "
             "± of a tornado row's change from these changes (95 %) |", "| --- | --- | --- | --- | --- | --- |"]
    for r in runs:
        for row in r["rows"]:
            name, unit = DISPLAY.get(r["task"], {}).get(row["metric"], (row["metric"], ""))
            name = name.replace("|", "\\|")  # a table cell
            fmt = (lambda v: "—" if v is None else f"{v:.2g} {unit}".rstrip())  # noqa: E731
            lines.append(f"| {r['design']} | {row['label'].replace('_psf', ' PSF')} | {name} | "
                         f"{fmt(row['max_scene_change'])} | {fmt(row['mean_change'])} | "
                         f"{fmt(row['ci95_half_width'])} |")
    lines += ["", "The PSF metric changed by " + ", ".join(f"{r['psf_metric_change']:.1e} ({r['design']})"
                                                        for r in runs) + "."]
    return "\n".join(lines + [""])


def main() -> None:
    from doefab.io import atomic_write_json, atomic_write_text

    code = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip()
    runs = []
    for name in DESIGNS:
        runs.append(compare(name))
        print(name, json.dumps(runs[-1]["rows"][:2]), flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    atomic_write_json(OUT / "judge_rounding.json", {"code": code, "part_seed": PART_SEED, "runs": runs})
    atomic_write_text(OUT / "judge_rounding.md", markdown(runs, code))
    print(f"wrote {OUT / 'judge_rounding.md'}")


def tables_only() -> None:
    """judge_rounding.md again from the committed judge_rounding.json (its code and numbers), with this code's
    metric names and units."""
    from doefab.io import atomic_write_text

    done = json.loads((OUT / "judge_rounding.json").read_text())
    atomic_write_text(OUT / "judge_rounding.md", markdown(done["runs"], done["code"]))
    print(f"wrote {OUT / 'judge_rounding.md'}")


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--one":
        judge_once(sys.argv[2], int(sys.argv[3]), sys.argv[4])
    elif sys.argv[1:] == ["--tables-only"]:
        tables_only()
    else:
        main()
