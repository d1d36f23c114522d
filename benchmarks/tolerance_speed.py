"""Samples per minute of PSF-level and network-level tolerance studies per task, and a 2-worker Dask
LocalCluster against the in-process run (same seed, same numbers, measured side by side).
Writes benchmarks/results/tolerance_speed.md. Run: .venv/bin/python benchmarks/tolerance_speed.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

OUT = Path(__file__).parent / "results"


def main(samples: int = 4):
    from doefab.tolerance import study
    from doefab.tolerance.errors import load_budget

    budget = load_budget()
    rows = ["| design | level | samples | wall time (s) | samples / minute |", "| --- | --- | --- | --- | --- |"]
    for design in ("streak", "grating", "half-ring"):
        ddir = f"masks/{design}/design"
        study._judge(ddir, 1)  # set-up (PSF plan, nominal PSF) not counted
        for networks in (False, True):
            with tempfile.TemporaryDirectory() as tmp:
                if networks:
                    study._network_judge(ddir, 1)
                t = time.perf_counter()
                study.monte_carlo(ddir, budget, samples, tmp, seed=0, progress=False, networks=networks)
                dt = time.perf_counter() - t
            rows.append(f"| {design} | {'network' if networks else 'PSF'} | {samples} | {dt:.1f} | "
                        f"{60 * samples / dt:.1f} |")
            print(rows[-1], flush=True)
    rows += ["", "| backend (grating, PSF level) | samples | wall time (s) | same numbers as in process |",
             "| --- | --- | --- | --- |"]
    ddir = "masks/grating/design"
    n = 8
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        a = study.monte_carlo(ddir, budget, n, Path(tmp) / "a", seed=3, progress=False)
        t_a = time.perf_counter() - t
        t = time.perf_counter()
        b = study.monte_carlo(ddir, budget, n, Path(tmp) / "b", seed=3, progress=False, scheduler="local:2")
        t_b = time.perf_counter() - t
    # in process torch uses both cores, a worker one thread: float32 sums may round differently
    diff = max(abs(x["metric"] - y["metric"]) for x, y in zip(a, b))
    same = "yes, bit for bit" if diff == 0 else (f"yes to {diff:.1e} (float32 rounding)" if diff < 1e-6 else
                                                 f"NO: differ by up to {diff:.2e}")
    rows.append(f"| in process (judge already built) | {n} | {t_a:.1f} | — |")
    rows.append(f"| Dask LocalCluster, 2 workers (includes start-up and each worker's PSF set-up) | {n} | {t_b:.1f} | "
                f"{same} |")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "tolerance_speed.md").write_text("\n".join(rows) + "\n")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
