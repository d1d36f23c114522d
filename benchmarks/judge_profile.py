"""Where a network-judged part's time goes: one part drawn from the default budget, judged through each committed
design's proposed network as ``doefab tolerance --networks`` judges it (``doefab.tolerance.netjudge``: the
judge's default scenes, each reconstructed twice — the network told the nominal PSF and the part's own pair),
profiled with cProfile after one warm-up part (the error-free part's scenes and the networks' set-up are not
counted). One torch thread and freed memory kept for reuse (``doefab.keep_freed_memory``), as the judge
computes. Cumulative seconds of each stage; the stages nest as listed
(a sub-stage's time is inside its stage's).

Writes benchmarks/results/judge_profile.{md,json}. Run with nothing else on the machine:
    .venv/bin/python benchmarks/judge_profile.py
"""

from __future__ import annotations

import cProfile
import pstats
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = Path(__file__).parent / "results"
DESIGNS = ("streak", "grating", "half-ring")

# (label, module path under doefab/, function name, depth): the stages of one judged part
STAGES = (
    ("the part's PSF pair (both halves, the network's kernel; depth: also the rendering planes)",
     "tolerance/netjudge.py", "pair", 0),
    ("scenes and their captures (``specs.make_batch``)", "reconstruction/specs.py", "make_batch", 0),
    ("scene content", "reconstruction/data.py", "hdr_sample", 1),
    ("scene content", "reconstruction/data.py", "spectral_sample", 1),
    ("scene content", "reconstruction/data.py", "depth_sample", 1),
    ("captures through the part (``render_layers``)", "imaging/captures.py", "render_layers", 1),
    ("crosstalk and its calibration", "tolerance/conditions.py", "crosstalk_for", 1),
    ("reconstruction (every call of the network)", "reconstruction/loader.py", "__call__", 0),
    ("highlight solve (``solve_highlights``)", "reconstruction/highlights.py", "solve_highlights", 1),
    ("illuminant mixture (``mix_illuminants``)", "reconstruction/illuminant.py", "mix_illuminants", 1),
    ("Wiener deconvolution", "reconstruction/wiener.py", "wiener_deconvolve", 1),
    ("cross-blur cost volume", "reconstruction/costvolume.py", "cross_blur_cost", 1),
    ("metrics", "reconstruction/metrics.py", "metrics_for", 0),
)


def cumulative(stats: pstats.Stats, module: str, func: str) -> float | None:
    """Cumulative seconds of ``func`` in ``doefab/<module>`` (None: not called)."""
    total, seen = 0.0, False
    for (path, _, name), (_, _, _, ct, _) in stats.stats.items():
        if name == func and path.replace("\\", "/").endswith("doefab/" + module):
            total, seen = total + ct, True
    return total if seen else None


def profile_design(name: str) -> dict:
    import numpy as np
    import torch

    from doefab._memory import keep_freed_memory
    from doefab.tolerance import study
    from doefab.tolerance.errors import load_budget, sample_errors
    from doefab.tolerance.netjudge import NetworkJudge

    torch.set_num_threads(1)
    keep_freed_memory()  # as ``doefab tolerance`` judges (tolerance.report.run_study)
    judge = NetworkJudge(study.judge_for(str(ROOT / "masks" / name / "design"), 1))
    budget = load_budget()
    parts = [sample_errors(budget, np.random.default_rng(s), seed=s, n_masks=judge.base.n_masks) for s in (1, 2)]
    t = time.perf_counter()
    judge.evaluate(parts[0])  # warm-up: set-up, caches
    warm = time.perf_counter() - t
    prof = cProfile.Profile()
    t = time.perf_counter()
    prof.runcall(judge.evaluate, parts[1])
    wall = time.perf_counter() - t
    stats = pstats.Stats(prof)
    rows = [{"stage": label, "depth": depth, "seconds": s} for label, mod, func, depth in STAGES
            if (s := cumulative(stats, mod, func)) is not None]
    return {"design": name, "task": judge.task, "scenes": judge.images, "size_px": judge.size,
            "reconstructions": 2 * judge.images, "warm_up_s": warm, "part_s": wall, "stages": rows}


def markdown(runs: list[dict], code: str) -> str:
    lines = ["# Where a network-judged part's time goes", "",
             f"Produced by `.venv/bin/python benchmarks/judge_profile.py` at {code}: one part drawn from the default "
             "budget, after a warm-up part, through each committed design's proposed network (torch on 1 thread and "
             "freed memory kept for reuse, as `doefab tolerance` runs; cProfile's cumulative seconds; a sub-stage's "
             "time is inside its stage's, and the profiler adds its own overhead).", ""]
    for r in runs:
        lines += [f"**{r['design']}** ({r['task']}): {r['part_s']:.1f} s for the part "
                  f"({60 / r['part_s']:.2f} parts / minute on one core), {r['scenes']} scenes of {r['size_px']}² px, "
                  f"{r['reconstructions']} reconstructions", "", "| stage | s | share of the part |",
                  "| --- | --- | --- |"]
        for s in r["stages"]:
            pad = "&nbsp;&nbsp;↳ " if s["depth"] else ""
            lines.append(f"| {pad}{s['stage']} | {s['seconds']:.1f} | {100 * s['seconds'] / r['part_s']:.0f} % |")
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    from doefab.io import atomic_write_json, atomic_write_text

    code = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip()
    runs = []
    for name in DESIGNS:
        runs.append(profile_design(name))
        print(f"{name}: {runs[-1]['part_s']:.1f} s per part", flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    atomic_write_json(OUT / "judge_profile.json", {"code": code, "threads": 1, "runs": runs})
    atomic_write_text(OUT / "judge_profile.md", markdown(runs, code))
    print(f"wrote {OUT / 'judge_profile.md'}")


if __name__ == "__main__":
    main()
