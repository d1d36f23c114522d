"""Wall time of the main job: the three shipped scenes end to end, as on a fresh clone (an empty doefab cache, so
every fabricated part's PSFs are computed; a fresh output folder), the one command the README gives:

    doefab run scenes/depth.toml scenes/hdr.toml scenes/hyperspectral.toml

(run in a fresh folder, so it writes out/run/<scene>/ there; it runs each scene in a process of its own, ``--jobs``
of them at a time: by default one; the longest scene first).

Run with nothing else on the machine: .venv/bin/python benchmarks/run_time.py [--quick] [--jobs N]

Writes benchmarks/results/run_time.md (run_time_side_by_side.md where scenes ran side by side; _quick with
--quick): seconds per scene and per stage, and the total,
from each run's run.json; the largest resident memory of any one of its processes, and the job's peak memory:
the machine's memory in use (MemTotal − MemAvailable), sampled every second, above what was in use before it
started (so run it with nothing else on the machine).
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
SCENES = ("depth", "hdr", "hyperspectral")  # the longest first: it sets the job's time when scenes run side by side
STAGES = ("design", "masks", "holder", "reconstruction", "tolerance")


def memory_in_use_bytes() -> int:
    """The machine's memory in use and not reclaimable: MemTotal − MemAvailable (Linux /proc/meminfo)."""
    info = {ln.split(":")[0]: int(ln.split()[1]) * 1024 for ln in Path("/proc/meminfo").read_text().splitlines()}
    return info["MemTotal"] - info["MemAvailable"]


def peak_while(proc: subprocess.Popen, baseline: int, every_s: float = 1.0) -> int:
    """Wait for ``proc``, sampling the machine's memory in use; returns the largest sample above ``baseline``."""
    peak = [0]

    def sample():
        while proc.poll() is None:
            peak[0] = max(peak[0], memory_in_use_bytes() - baseline)
            time.sleep(every_s)

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    proc.wait()
    t.join()
    return peak[0]


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--jobs", default="1", help="doefab run --jobs (default 1: one scene after another)")
    args = ap.parse_args()
    quick = args.quick
    work = ROOT / "out" / ("bench_run_quick" if quick else "bench_run")
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    runs = work / "out" / "run"
    with tempfile.TemporaryDirectory() as cache:  # one cache for the three scenes, as one command has
        env = {**os.environ, "DOEFAB_CACHE": cache}
        baseline = memory_in_use_bytes()
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "doefab", "run",
                                 *(str(ROOT / "scenes" / f"{s}.toml") for s in SCENES), *(["--quick"] if quick else []),
                                 "--jobs", str(args.jobs)], cwd=work, env=env, stdout=(work / "stdout.txt").open("w"))
        job_gib = peak_while(proc, baseline) / 2**30
        said = (work / "stdout.txt").read_text()  # "N scenes, J at a time (...)" first when they run side by side
        total = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"the main job failed (exit status {proc.returncode})")
    peak_gib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20  # KiB on Linux
    rows = ["| scene | " + " | ".join(STAGES) + " | scene total (s) |", "| --- " * (len(STAGES) + 2) + "|"]
    inside = 0.0
    for s in SCENES:
        rec = json.loads((runs / s / "run.json").read_text())
        cells = [f"{rec['stages'][st]['seconds']:.0f}" if st in rec["stages"] else "—" for st in STAGES]
        rows.append(f"| {s} | " + " | ".join(cells) + f" | {rec['seconds']:.0f} |")
        inside += rec["seconds"]
    lanes = said.split(" at a time")[0].split(", ")[-1] if " at a time" in said else "1"
    how = (f"{lanes} scenes at a time, each torch on {said.split('torch on ')[1].split(' thread')[0]} thread(s): the "
           f"scenes' own totals add to {inside:.0f} s" if lanes != "1" else
           f"one scene after another: {total - inside:.0f} s of it lie outside the scenes' own totals (each scene runs "
           f"in a process of its own: starting Python and doefab, checking its scene file)")
    text = (f"The main job{' with --quick' if quick else ''} from an empty cache (`.venv/bin/python "
            f"benchmarks/run_time.py{' --quick' if quick else ''} --jobs {args.jobs}`: `doefab run "
            f"{' '.join(f'scenes/{s}.toml' for s in SCENES)} --jobs {args.jobs}`), seconds per stage on this "
            f"{os.cpu_count()}-core machine.\n\n"
            + "\n".join(rows) + f"\n\nThe three scenes together: {total:.0f} s ({total / 60:.1f} min), {how}; the "
            f"largest resident memory of any one process: {peak_gib:.1f} GiB; the job's peak memory (the machine's "
            f"memory in use above what it was before, sampled every second): {job_gib:.1f} GiB.\n")
    from doefab.io import atomic_write_text

    name = "run_time" + ("_quick" if quick else "") + ("_side_by_side" if lanes != "1" else "")
    atomic_write_text(OUT / f"{name}.md", text)
    print(text)


if __name__ == "__main__":
    main()
