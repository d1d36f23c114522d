"""A committed design's own run, timed again: its recorded settings, this code against a previous revision.

For ``--task`` (default half-ring): the committed design's settings as its design.json records them (task
parameters, optimiser, steps, sampling, parameterization, batch, seed, …) are run from the task's start with
this code and with the package as of git revision ``--baseline REV`` (a temporary worktree; default: the
revision that committed the design's mask set), each in a fresh process on ``--threads`` torch threads, the two
taking turns ``--rounds`` times in alternating order. Reported per code: the median wall time of the design run
(``design.extra["wall_time_s"]``) and the 16-level metric of its result on the full grid, beside the committed
design's recorded ones. Settings a revision does not know are left out for it (and listed).

Writes benchmarks/results/design_time_<task>.{md,json} (design_time_half-ring.md for the default task).
Run: .venv/bin/python benchmarks/design_time.py --task half-ring --baseline REV
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from revisions import ROOT, add_arguments, code_root, measure_at, same_code_warning, turns  # this folder is on the path

sys.path.insert(0, code_root())  # the package measured (a baseline's worktree)

def committed(task: str) -> dict:
    """The committed design's recorded settings, wall time and 16-level metric."""
    from doefab.design.committed import committed_dir
    from doefab.design.design import Design

    d = Design.load(committed_dir(task))
    return {"config": d.extra["config"], "wall_time_s": float(d.extra["wall_time_s"]),
            "quantized": float(d.metrics["quantized"])}


def measure(args) -> dict:
    """One design run with the committed settings: {wall_time_s, quantized, dropped settings}."""
    import dataclasses

    import torch

    import doefab
    from doefab.design.optimize import DesignConfig

    torch.set_num_threads(args.threads)
    cfg = json.loads(args.config)
    known = {f.name for f in dataclasses.fields(DesignConfig)}
    fixed = ("task", "iterations", "optimizer", "seed")
    settings = {k: v for k, v in cfg.items() if k in known and k not in fixed}
    d = doefab.optimize(cfg["task"], iterations=cfg["iterations"], optimizer=cfg["optimizer"], seed=cfg["seed"],
                        progress=False, **settings)
    return {"wall_time_s": float(d.extra["wall_time_s"]), "quantized": float(d.metrics["quantized"]),
            "dropped": sorted(k for k in cfg if k not in known)}


def table(r: dict) -> str:
    a, c = r["settings"], r["committed"]
    cfg = c["config"]
    lines = [f"`.venv/bin/python benchmarks/design_time.py --task {a['task']} --baseline {r['baseline_revision']}`: "
             f"the committed {a['task']} design's own settings ({cfg['optimizer']}, {cfg['iterations']} steps, "
             f"{cfg.get('parameterization', 'pixel')}, sampling {cfg.get('sampling', 1)}, batch {cfg.get('batch', 0)}, "
             f"seed {cfg['seed']}) run again with each code, torch on {a['threads']} threads, median of "
             f"{a['rounds']} runs each (the codes taking turns in alternating order, each run in a fresh process).",
             "", "| code | design run wall time (s) | 16-level metric (full grid) |", "| --- | --- | --- |",
             f"| the committed design, as recorded | {c['wall_time_s']:.0f} | {c['quantized']:.4f} |"]
    for key, label in (("baseline", "previous code"), ("this_code", "this code")):
        runs = r["runs"][key]
        if runs:
            rev = r["baseline_revision"] if key == "baseline" else r["revision"]
            lines.append(f"| {label} ({rev}) | {statistics.median(x['wall_time_s'] for x in runs):.0f} | "
                         f"{statistics.median(x['quantized'] for x in runs):.4f} |")
    return "\n".join(lines + [""])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--task", default="half-ring", choices=["streak", "grating", "half-ring"])
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--config", help=argparse.SUPPRESS)
    add_arguments(ap, None, "git revision timed beside this code ('none': skip; default: the revision that last "
                  "changed the design's committed design.json)")
    args = ap.parse_args(argv)
    if args.measure_only:
        print(json.dumps(measure(args)))
        return 0
    from doefab.io import atomic_write_json, atomic_write_text

    ref = committed(args.task)
    base = args.baseline or subprocess.run(
        ["git", "-C", str(ROOT), "log", "-1", "--format=%h", "--", f"masks/{args.task}/design/design.json"],
        check=True, capture_output=True, text=True).stdout.strip()
    argv_run = ["--config", json.dumps(ref["config"]), "--threads", str(args.threads)]
    runs, revs = {"baseline": [], "this_code": []}, {}
    for code in turns(base, args.rounds):
        key = "this_code" if code is None else "baseline"
        revs[key], got = measure_at(code, __file__, argv_run)
        runs[key].append(got)
        print(key, revs[key], got, file=sys.stderr, flush=True)
    if "baseline" in revs:
        same_code_warning(revs["baseline"], revs["this_code"])
    result = {"settings": {**vars(args), "cpus": os.cpu_count()}, "committed": ref, "runs": runs,
              "revision": revs["this_code"], "baseline_revision": revs.get("baseline", "none")}
    out = Path(args.results)
    atomic_write_json(out / f"design_time_{args.task}.json", result)
    atomic_write_text(out / f"design_time_{args.task}.md", table(result))
    print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
