"""The memory of a diagnosis's parts with and without the PSF judge's reuse cache.

A part model (``doefab.lab.partmodel.PartModel``) computes thousands of parts in one fit, nearly all new. Its
judges keep only the latest part's PSFs (``partmodel.JUDGE_KEEP_BYTES``); the judge's own default
(``PSFJudge.KEEP_BYTES``, 256 MB) served them nothing and, holding small PSFs among each part's large transient
buffers, fragmented the heap. This measures both on a whole design: a 25 mm f/5.6 camera (3.5 µm DOE pixels,
1276² grid), 4 levels, 3 bands, its streak design made by ``doefab run`` (design and masks, 60 iterations), a part
with mask 1 etched 6 % deep, 0.2 mm decenter and 1° mount rotation recorded by ``lab.simulate`` and calibrated
by ``doefab calibrate``. Each setting runs in its own process (glibc's freed-memory setting as every doefab command
applies it) and computes the same ``--parts`` parts: the fit's starts drawn from the budget in turn, each moved by
a small random step, as a fit's residuals ask for them. It records the resident memory every 50 parts and the
seconds per part.

    OMP_NUM_THREADS=2 .venv/bin/python benchmarks/diagnose_memory.py            # about 6 minutes on 2 cores

Options: ``--parts`` (400), ``--work`` (out/bench/diagnose_memory). Writes benchmarks/results/diagnose_memory.md
and .json. Torch runs on 2 threads.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
DOEFAB = [sys.executable, "-m", "doefab"]
SCENE = """task = "hdr"
stages = ["design", "masks"]
[camera]
focal_length_mm = 25.0
f_number = 5.6
lens_f_number = 2.0
focus_distance_m = 5.0
sensor_pitch_um = 3.76
sensor_diagonal_mm = 28.2
doe_pitch_um = 3.5
[optics]
wavelengths_nm = [656, 589, 486]
[design]
iterations = 60
sampling = 2
[fabrication]
n_levels = 4
material = "fused silica"
min_feature_um = 2.0
"""


def _rss_gb() -> float:
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) * 1024 / 1e9
    return float("nan")


def prepare(work: Path) -> tuple[Path, Path]:
    """(mask set, measured pair) of the benchmark's part, made once under ``work``."""
    from doefab.lab.simulate import write_lab_recordings
    from doefab.tolerance.errors import PartErrors

    work.mkdir(parents=True, exist_ok=True)
    (work / "camera.toml").write_text(SCENE)
    subprocess.run(DOEFAB + ["run", str(work / "camera.toml"), "--out", str(work / "run")], check=True)
    masks, rec, cal = work / "run" / "masks", work / "recordings", work / "calibration"
    if not (rec / "recordings.toml").is_file():
        err = PartErrors(depth_scale=(1.06, 1.0), mount_shift=(0.2e-3, 0.0), mount_rotation=math.radians(1.0))
        write_lab_recordings(rec, masks, err)
    if not (cal / "psf_pair.npz").is_file():
        subprocess.run(DOEFAB + ["calibrate", str(rec / "recordings.toml"), "--out", str(cal)], check=True)
    return masks, cal / "psf_pair.npz"


def child(masks: str, pair: str, keep: str, parts: int) -> dict:
    """One setting in this process: ``keep`` "judge" (the judge's default cache) or "model" (the part model's)."""
    import numpy as np
    import torch

    import doefab
    from doefab.lab import diagnose as dg
    from doefab.lab.partmodel import PartModel
    from doefab.optics.psf import PSFPair
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.judge import PSFJudge

    doefab.keep_freed_memory()
    torch.set_num_threads(2)
    model = PartModel(Path(masks), PSFPair.load(pair), load_budget(None))
    if keep == "judge":
        model.judge.KEEP_BYTES = PSFJudge.KEEP_BYTES
    starts, rng = dg._starts(model, dg.STARTS, 0), np.random.default_rng(0)
    trace, t0 = [], time.perf_counter()
    for i in range(parts):
        model.residual(starts[1 + i % (len(starts) - 1)] + 0.01 * rng.standard_normal(len(starts[0])))
        if (i + 1) % 50 == 0:
            trace.append([i + 1, round(_rss_gb(), 3)])
    kept = sum(v.nbytes for v in model.judge._kept.values()) / 1e9
    return {"keep": keep, "keep_bytes": model.judge.KEEP_BYTES, "parts": parts, "rss_gb": trace, "kept_gb": kept,
            "seconds_per_part": (time.perf_counter() - t0) / parts, "grid": model.judge.design.camera.doe_pixels}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", type=int, default=400)
    ap.add_argument("--work", default=str(ROOT / "out" / "bench" / "diagnose_memory"))
    ap.add_argument("--child", nargs=4, metavar=("MASKS", "PAIR", "KEEP", "PARTS"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(child(a.child[0], a.child[1], a.child[2], int(a.child[3]))))
        return
    masks, pair = prepare(Path(a.work))
    rows = []
    for keep in ("judge", "model"):
        out = subprocess.run([sys.executable, __file__, "--child", str(masks), str(pair), keep, str(a.parts)],
                             check=True, capture_output=True, text=True).stdout
        rows.append(json.loads(out.strip().splitlines()[-1]))
        print(rows[-1], flush=True)
    write(rows)


def write(rows: list[dict]) -> None:
    from doefab.io import atomic_write_json, atomic_write_text

    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic_write_json(RESULTS / "diagnose_memory.json", {"rows": rows, "threads": 2})
    marks = [n for n, _ in rows[0]["rss_gb"]]
    head = "| cache | " + " | ".join(f"{n} parts" for n in marks) + " | PSFs kept at the end | s per part |"
    lines = ["The resident memory of a diagnosis's parts (GB) with the PSF judge's reuse cache and with the part "
             f"model's (a {rows[0]['grid']}² grid, 4 levels, 3 bands; `OMP_NUM_THREADS=2 .venv/bin/python "
             "benchmarks/diagnose_memory.py`, 2 threads, each setting in its own process).", "",
             head, "| --- " * (len(marks) + 3) + "|"]
    words = {"judge": "the judge's (256 MB)", "model": "the part model's (latest part only)"}
    for r in rows:
        lines.append(f"| {words[r['keep']]} | " + " | ".join(f"{g:.2f}" for _, g in r["rss_gb"])
                     + f" | {r['kept_gb']:.3f} | {r['seconds_per_part']:.2f} |")
    grow = rows[0]["rss_gb"][-1][1] - rows[0]["rss_gb"][0][1]
    lines += ["", f"With the judge's cache the process grew by {grow:.2f} GB from part {marks[0]} to part "
              f"{marks[-1]}, while the PSFs the cache held at the end took {rows[0]['kept_gb']:.3f} GB: the rest is "
              "the heap around them, which the parts' large transient buffers could no longer reuse."]
    atomic_write_text(RESULTS / "diagnose_memory.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
