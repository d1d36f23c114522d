"""Speed of the reconstruction stage on this machine, per task: capture simulation of a 512 × 512 scene,
reconstruction of a 512 × 512 capture pair with the shipped proposed network (target ≤ 1 s each), the first
call of a freshly loaded network beside the median of later calls (a per-call setup cost shows as both being
high), and training steps per second (from the shipped weights' records). Medians of ``--repeats`` runs on
``--threads`` torch threads, in a process that keeps the memory it frees as every ``doefab`` command does
(``doefab.keep_freed_memory``). Split used: one validation scene per task (only its size matters: no choice is made
on it).

``--baseline REV`` (default HEAD) times the same in the same run with the package as of git revision REV (a
temporary worktree), for a before-and-after table; ``--baseline none`` skips it. The two codes take turns,
``--rounds`` times each in alternating order (the machine's load drifts), and each figure is the median over
the rounds.

Writes benchmarks/results/reconstruction_speed.{md,json}.
Run: .venv/bin/python benchmarks/reconstruction_speed.py --baseline REV
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from revisions import (add_arguments, code_root, measure_at, median_time, same_code_warning,  # this folder is on
                       turns)  # the path of a script run

sys.path.insert(0, code_root())  # the package measured (a baseline's worktree)

TASKS = ("hdr", "hyperspectral", "depth")


def scene_captures(task: str):
    """A function that simulates the capture pair of ``task``'s first 512² validation scene through the committed
    design (what the benchmark times; also the frame other benchmarks reconstruct)."""
    import doefab
    from doefab.reconstruction.data import depth_sample, hdr_sample, sample_rng, spectral_sample
    from doefab.reconstruction.specs import psf_pair

    pair, _ = psf_pair(task)
    rng = sample_rng("val", 0)
    depth = response = None
    if task == "hdr":
        scene = hdr_sample(rng, 512, "val")
    elif task == "hyperspectral":
        scene = spectral_sample(rng, 512, "val")
        response = doefab.sensor_response(pair.wavelengths)
    else:
        scene, depth = depth_sample(rng, 512, "val")
    return lambda: doefab.simulate_captures(scene, pair, depth_map=depth, response=response)


def measure(args) -> dict:
    """{task: {simulate_s, first_call_s, reconstruct_s, steps_per_s, crop_px}} with the package on the path."""
    import torch

    import doefab

    torch.set_num_threads(args.threads)
    try:  # as every doefab command runs (a previous code without the setting is timed as it ran)
        from doefab._memory import keep_freed_memory
    except ImportError:
        pass
    else:
        keep_freed_memory()
    out = {}
    for task in args.task or TASKS:
        simulate = scene_captures(task)
        sim = median_time(simulate, args.repeats)
        coded, uncoded = simulate()
        rec = doefab.load_reconstructor(task)
        t = time.perf_counter()
        rec(coded, uncoded)
        first = time.perf_counter() - t
        recon = median_time(lambda: rec(coded, uncoded), args.repeats)
        tr = rec.meta["training"]
        out[task] = {"simulate_s": sim, "first_call_s": first, "reconstruct_s": recon,
                     "steps_per_s": tr["steps"] / tr["wall_time_s"], "crop_px": tr["crop_px"]}
        print(task, out[task], file=sys.stderr, flush=True)
    return out


def _median_rounds(rounds: list[dict]) -> dict:
    """Each task's figures, the median over the rounds."""
    import statistics

    return {task: {k: statistics.median(r[task][k] for r in rounds) for k in rounds[0][task]} for task in TASKS}


def _ratio(r: dict, task: str) -> str:
    """Median over the rounds of this code's reconstruction time over the previous code's in the same round (each
    code's three tasks in turn, the order alternating from round to round), so the machine's drift from round to
    round cancels."""
    import statistics

    rounds = r["rounds"]
    if not rounds["baseline"]:
        return "—"
    pairs = zip(rounds["this_code"], rounds["baseline"])
    return f"{statistics.median(n[task]['reconstruct_s'] / o[task]['reconstruct_s'] for n, o in pairs):.2f}"


def table(r: dict) -> str:
    a = r["settings"]
    before = r.get("baseline")
    rev = before["revision"] if before else "none"
    runs = (([(f"previous code ({rev})", before["tasks"])] if before else [])
            + [(f"this code ({r.get('revision', '?')})", r["tasks"])])
    rounds = f" --rounds {a['rounds']}" if a["rounds"] != 3 else ""
    order = "the codes taking turns in alternating order, " if before else ""
    lines = [f"`.venv/bin/python benchmarks/reconstruction_speed.py --baseline {rev}{rounds}`: torch {a['torch']} on "
             f"{a['threads']} threads, medians of {a['repeats']} runs in each of {a['rounds']} rounds ({order}each "
             "task in a fresh process, which keeps the memory it frees where the code does so: "
             "`doefab.keep_freed_memory`, as every doefab command) and the median over the rounds; the shipped "
             "proposed networks; target ≤ 1 s per 512² reconstruction.", "",
             "| task | code | capture simulation, 512² (s) | reconstruction, 512² (s) | first call of a loaded "
             "network (s) | reconstruction, this code / previous (median of the rounds' ratios) | training steps / s "
             "(batch 4) | training crop (px) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for task in TASKS:
        for name, tasks in runs:
            t = tasks[task]
            ratio = _ratio(r, task) if tasks is r["tasks"] else ""
            lines.append(f"| {task} | {name} | {t['simulate_s']:.2f} | {t['reconstruct_s']:.2f} | "
                         f"{t['first_call_s']:.2f} | {ratio} | {t['steps_per_s']:.2f} | {t['crop_px']:.0f} |")
    return "\n".join(lines + [""])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--task", action="append", choices=TASKS, help=argparse.SUPPRESS)
    add_arguments(ap)
    args = ap.parse_args(argv)
    if args.measure_only:
        print(json.dumps(measure(args)))
        return 0
    import torch

    from doefab.io import atomic_write_json, atomic_write_text

    revs, old, new = {}, [], []
    for code in turns(args.baseline, args.rounds):  # each task in a fresh process
        got = {}
        for task in TASKS:
            revs[code], one = measure_at(code, __file__, ["--task", task, "--repeats", str(args.repeats),
                                                          "--threads", str(args.threads)])
            got.update(one)
        (new if code is None else old).append(got)
    sha = revs.get(args.baseline)
    if sha:
        same_code_warning(sha, revs[None])
    result = {"settings": {**vars(args), "torch": torch.__version__, "cpus": os.cpu_count()},
              "revision": revs[None], "tasks": _median_rounds(new), "rounds": {"this_code": new, "baseline": old},
              "baseline": {"revision": sha, "tasks": _median_rounds(old)} if old else None}
    out = Path(args.results)
    atomic_write_json(out / "reconstruction_speed.json", result)
    atomic_write_text(out / "reconstruction_speed.md", table(result))
    print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
