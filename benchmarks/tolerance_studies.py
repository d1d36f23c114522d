"""The committed designs' tolerance studies at PSF level under the default budget: every error kind swept alone,
the tornado at one standard deviation of the budget, a Monte Carlo of 24 parts with the yield and its Wilson interval, and the
quantization study, for the streak, the grating and the half-ring design:

    doefab tolerance --design masks/DESIGN --samples 24 --sweep --levels --workers 1 --out out/tol/DESIGN

Run: .venv/bin/python benchmarks/tolerance_studies.py [streak grating half-ring]

Copies each study's report.md and its figures (tornado.png, sweeps.png, yield_vs_n.png, quantization.png) to
benchmarks/results/tolerance_DESIGN/, and writes benchmarks/results/tolerance_studies.md: one line per design
(nominal PSF metric, Monte Carlo mean, yield and interval, the three largest single losses), and the git revision
each row was measured at (a design not named keeps its published row and revision).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
FIGURES = ("tornado.png", "sweeps.png", "yield_vs_n.png", "quantization.png")
DESIGNS = ("streak", "grating", "half-ring")


def study(design: str) -> dict:
    out = ROOT / "out" / "tol" / design
    # one process: two worker processes at the grid the study picks for the grating exceed this machine's 23 GB;
    # an interrupted study resumes its finished steps and parts (``--resume``: the same inputs only)
    subprocess.run([sys.executable, "-m", "doefab", "tolerance", "--design", f"masks/{design}", "--samples", "24",
                    "--sweep", "--levels", "--workers", "1", "--out", str(out),
                    "--resume" if (out / "tolerance.json").is_file() or (out / "steps").is_dir() else "--force"],
                   check=True, cwd=ROOT)
    dest = OUT / f"tolerance_{design.replace('-', '')}"
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("report.md", *FIGURES):
        if (out / name).is_file():
            shutil.copyfile(out / name, dest / name)
    return json.loads((out / "tolerance.json").read_text())


def line(design: str, res: dict) -> str:
    s = res["summary"]
    top = "; ".join(f"{r['error']} {r['value']:.3g} {r['unit']} {r['delta']:+.3f}"
                    for r in [r for r in res["tornado"] if r["delta"] < 0][:3])
    return (f"| {design} | {res['nominal']['psf']['psf_metric']:.3f} | {s['metric']['mean']:.3f} "
            f"({s['metric']['ci95'][0]:.3f}–{s['metric']['ci95'][1]:.3f}) | {res['spec']['psf']} | "
            f"{s['yield']['value']:.2f} ({s['yield']['ci95'][0]:.2f}–{s['yield']['ci95'][1]:.2f}) | {top} |")


def _kept_rows() -> tuple[dict, dict]:
    """({design: its row}, {design: the git revision it was measured at}) of the published file, for the designs a
    run leaves out."""
    path = OUT / "tolerance_studies.md"
    if not path.is_file():
        return {}, {}
    text = path.read_text()
    rows = [r for r in text.splitlines() if r.startswith("| ") and not r.startswith("| design")]
    revs = dict(re.findall(rf"({'|'.join(DESIGNS)}) at git ([0-9a-f]+(?:\+changes)?)", text))
    return {r.split("|")[1].strip(): r for r in rows if not r.startswith("| ---")}, revs


def _revision() -> str:
    """The short git revision of the code measured, with ``+changes`` where the package or the benchmark scripts in
    the working tree differ from it."""
    rev = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "doefab", "benchmarks/*.py"],
                           cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()  # the code, not results
    return rev + ("+changes" if dirty else "")


def main() -> None:
    designs = sys.argv[1:] or list(DESIGNS)
    rows = ["| design | nominal PSF metric | mean of 24 parts (95 % t interval) | spec | yield (Wilson 95 %) | "
            "largest single losses at the budget's 1σ |", "| --- | --- | --- | --- | --- | --- |"]
    kept, revs = _kept_rows()
    rev = _revision()
    for d in DESIGNS:
        if d in designs:
            rows.append(line(d, study(d)))
            revs[d] = rev
            print(rows[-1], flush=True)
        elif d in kept:  # a design not re-run this time keeps its published row
            rows.append(kept[d])
    measured = ", ".join(f"{d} at git {revs[d]}" for d in DESIGNS if d in revs)
    text = ("Tolerance of the committed designs under the default budget, PSF level (`.venv/bin/python "
            "benchmarks/tolerance_studies.py`; each row: `doefab tolerance --design masks/DESIGN --samples 24 --sweep "
            "--levels`).\n\n" + "\n".join(rows) + "\n\n"
            f"Measured {measured}; one worker process; each kind in the tornado at one standard deviation of the "
            "budget's draws (the mask overlay at the rms length of a plate's 2-D shift); a sensor's crosstalk in "
            "every part. The means' intervals are Student's t over the 24 parts (t₀.₉₇₅ at 23 degrees of freedom), "
            "as each study's report (`tolerance_DESIGN/report.md`) prints them.\n")
    (OUT / "tolerance_studies.md").write_text(text)


if __name__ == "__main__":
    main()
