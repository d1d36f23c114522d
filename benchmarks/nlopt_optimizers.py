"""nlopt's L-BFGS and MMA on the half grid, 25 evaluations each (re-measured after the fix that makes them run
their whole budget: earlier rows reported the start design, because nlopt stopped after one evaluation
above ~2.1 M variables and the error was swallowed). Writes benchmarks/results/nlopt_optimizers.md.
Run: .venv/bin/python benchmarks/nlopt_optimizers.py
"""

from __future__ import annotations

import argparse
from pathlib import Path

OUT = Path(__file__).parent / "results"


def main(argv=None):
    import doefab

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--tasks", nargs="+", default=["streak", "grating", "half-ring"])
    ap.add_argument("--optimizers", nargs="+", default=["lbfgs", "mma"])
    ap.add_argument("--evaluations", type=int, default=25)
    args = ap.parse_args(argv)
    rows = ["| task | optimiser | evaluations run / budget | 16-level metric (full grid) | worst entry | wall time (s) "
            "| stop reason |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for task in args.tasks:
        for opt in args.optimizers:
            print(f"{task}: {opt} …", flush=True)
            d = doefab.optimize(task, iterations=args.evaluations, optimizer=opt, sampling=2, progress=False,
                                eval_every=5)
            m = d.metrics
            rows.append(f"| {task} | {opt} | {d.extra['evaluations']} / {args.evaluations} | {m['quantized']:.4f} | "
                        f"{m['quantized_worst']:.4f} | {d.extra['wall_time_s']:.0f} | "
                        f"{d.extra.get('stop_reason', 'budget reached')} |")
            print(rows[-1], flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "nlopt_optimizers.md").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
