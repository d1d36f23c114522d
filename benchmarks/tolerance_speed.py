"""How fast a tolerance study decides, and whether its surrogate agrees with the direct Monte Carlo.

``psf``: ``doefab tolerance --design masks/grating --samples 300`` (PSF level, default budget, grid chosen by the
study, default workers: one process per core); then ``--samples 0 --surrogate`` (the sensitivity surrogate,
checked on held-out parts of its own) — its yield interval against the direct run's.
``network``: parts per minute through each task's network (``--networks``, 6 parts each; the network judge
renders validation scenes — split used: val).
Writes benchmarks/results/tolerance_speed.{md,json}. Run with nothing else on the machine:
    .venv/bin/python benchmarks/tolerance_speed.py psf network
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

OUT = Path(__file__).parent / "results"
DOEFAB = [sys.executable, "-m", "doefab"]


def run(args: list[str], out: Path) -> tuple[dict, float]:
    t = time.perf_counter()
    subprocess.run(DOEFAB + ["tolerance", *args, "--out", str(out)], check=True, stdout=subprocess.DEVNULL)
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
    res, wall = run(["--design", "masks/grating", "--samples", "0", "--surrogate"], tmp / "surrogate")
    s = res["surrogate"]
    d = data["default"]["yield"]["ci95"]
    agree = s["yield"]["ci95"][0] <= d[1] and d[0] <= s["yield"]["ci95"][1]
    data["surrogate"] = {"wall_s": wall, **s, "agrees_with_direct": agree}
    h = s["yield"]["held_out"]
    rows.append(f"| doefab tolerance --design masks/grating --samples 0 --surrogate | {s['model']['parts']} fitted + "
                f"{h['n']} held out | {wall:.0f} | — | — | {s['yield']['value']:.3f} ({s['yield']['ci95'][0]:.3f}–"
                f"{s['yield']['ci95'][1]:.3f}) |")
    rows += ["", f"Surrogate: held-out RMSE {h['rmse']:.4f}, mean residual {h['bias']:+.4f} ± {h['bias_se']:.4f}; its "
                 f"yield interval {'overlaps' if agree else 'does NOT overlap'} the direct run's ({d[0]:.3f}–{d[1]:.3f})."]
    data["cores"] = cores
    return rows, data


def network_rows(tmp: Path) -> tuple[list[str], dict]:
    rows = ["| design | parts through the network | Monte Carlo (s) | parts / minute |", "| --- | --- | --- | --- |"]
    data = {}
    for name in ("streak", "grating", "half-ring"):
        res, _ = run(["--design", f"masks/{name}", "--samples", "6", "--networks", "--grid", "1"], tmp / name)
        data[name] = {"mc_s": res["monte_carlo_seconds"], "parts_per_minute": res["parts_per_minute"]}
        rows.append(f"| {name} | 6 | {res['monte_carlo_seconds']:.0f} | {res['parts_per_minute']:.2f} |")
        print(rows[-1], flush=True)
    return rows, data


def main(parts: list[str]):
    OUT.mkdir(parents=True, exist_ok=True)
    old = OUT / "tolerance_speed.json"
    data = json.loads(old.read_text()) if old.is_file() else {}
    text = {}
    with tempfile.TemporaryDirectory() as tmp:
        for part, fn in (("psf", psf_rows), ("network", network_rows)):
            if part in parts:
                rows, data[part] = fn(Path(tmp))
                if "cores" in data[part]:
                    data["cores"] = data[part]["cores"]
                data[part + "_rows"] = rows
    for part in ("psf", "network"):
        text[part] = data.get(part + "_rows", [])
    old.write_text(json.dumps(data, indent=1) + "\n")
    md = ["PSF level, committed grating design, default budget, on a machine with "
          f"{data.get('cores', '?')} cores (`.venv/bin/python benchmarks/tolerance_speed.py psf`):",
          "", *text["psf"], "", "Through the networks (`... tolerance_speed.py network`):", "", *text["network"]]
    (OUT / "tolerance_speed.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main(sys.argv[1:] or ["psf", "network"])
