"""Wall time of the main job: the three shipped scenes end to end, as on a fresh clone (an empty doefab cache, so
every fabricated part's PSFs are computed; a fresh output folder), the one command the README gives:

    doefab run scenes/hdr.toml scenes/hyperspectral.toml scenes/depth.toml

(run in a fresh folder, so it writes out/run/<scene>/ there; it runs each scene in a process of its own).

Run with nothing else on the machine: .venv/bin/python benchmarks/run_time.py [--quick]

Writes benchmarks/results/run_time.md (or run_time_quick.md): seconds per scene and per stage, and the total,
from each run's run.json; the largest resident memory of any one of its processes, and the job's peak memory:
the largest sum, sampled every second, of the proportional set size (shared pages split between the processes that
share them) over the command's whole process tree.
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
SCENES = ("hdr", "hyperspectral", "depth")
STAGES = ("design", "masks", "holder", "reconstruction", "tolerance")


def tree_pss_bytes(root: int) -> int:
    """Proportional set size summed over ``root`` and all its descendants (Linux /proc)."""
    children: dict = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            pid, ppid = int(stat.parent.name), int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        children.setdefault(ppid, []).append(pid)
    total, todo = 0, [root]
    while todo:
        pid = todo.pop()
        todo += children.get(pid, [])
        try:
            rollup = Path(f"/proc/{pid}/smaps_rollup").read_text()
        except OSError:
            continue
        total += sum(int(ln.split()[1]) * 1024 for ln in rollup.splitlines() if ln.startswith("Pss:"))
    return total


def peak_while(proc: subprocess.Popen, every_s: float = 1.0) -> int:
    """Wait for ``proc``, sampling its tree's summed PSS; returns the largest sample in bytes."""
    peak = [0]

    def sample():
        while proc.poll() is None:
            peak[0] = max(peak[0], tree_pss_bytes(proc.pid))
            time.sleep(every_s)

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    proc.wait()
    t.join()
    return peak[0]


def main() -> None:
    quick = "--quick" in sys.argv[1:]
    work = ROOT / "out" / ("bench_run_quick" if quick else "bench_run")
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    runs = work / "out" / "run"
    with tempfile.TemporaryDirectory() as cache:  # one cache for the three scenes, as one command has
        env = {**os.environ, "DOEFAB_CACHE": cache}
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "doefab", "run",
                                 *(str(ROOT / "scenes" / f"{s}.toml") for s in SCENES), *(["--quick"] if quick else [])],
                                cwd=work, env=env, stdout=subprocess.DEVNULL)
        job_gib = peak_while(proc) / 2**30
        total = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"the main job failed (exit status {proc.returncode})")
    peak_gib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20  # KiB on Linux
    rows = ["| scene | " + " | ".join(STAGES) + " | scene total (s) |", "| --- " * (len(STAGES) + 2) + "|"]
    for s in SCENES:
        rec = json.loads((runs / s / "run.json").read_text())
        cells = [f"{rec['stages'][st]['seconds']:.0f}" if st in rec["stages"] else "—" for st in STAGES]
        rows.append(f"| {s} | " + " | ".join(cells) + f" | {rec['seconds']:.0f} |")
    text = (f"The main job{' with --quick' if quick else ''} from an empty cache (`.venv/bin/python "
            f"benchmarks/run_time.py{' --quick' if quick else ''}`: `doefab run scenes/hdr.toml "
            f"scenes/hyperspectral.toml scenes/depth.toml`), seconds per stage on this 2-core machine.\n\n"
            + "\n".join(rows) + f"\n\nThe three scenes together: {total:.0f} s ({total / 60:.1f} min); the largest "
            f"resident memory of any one process: {peak_gib:.1f} GiB; the job's peak memory (summed proportional set "
            f"size of its processes, sampled every second): {job_gib:.1f} GiB.\n")
    from doefab.io import atomic_write_text

    atomic_write_text(OUT / ("run_time_quick.md" if quick else "run_time.md"), text)
    print(text)


if __name__ == "__main__":
    main()
