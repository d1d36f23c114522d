"""What a fabricated part's own PSF pair buys its networks: for each task, parts drawn from the shipped tolerance
budget (seeded), their PSF pairs computed by the tolerance model on a grid ``--supersample``× finer than the
design's (the stand-in for a measured ``psf_pair.npz``), and the task's validation scenes captured through each
part with the budget's dual-pixel crosstalk unmixed by a noisy calibration (``tolerance.conditions.measured``).
The shipped proposed network's task metric on those captures when it is

  (a) told the nominal pair (what it was trained with),
  (b) told the measured pair (``doefab evaluate --psf``),
  (c) told the measured pair after a network-only fine-tune on captures through it (``doefab finetune --psf
      --minutes M``: the shipped network as warm start, the training split's scenes, the DOE untouched).

The published table (about 30 minutes on 2 cores):

    .venv/bin/python benchmarks/measured_pair.py --parts 2 --images 8 --minutes 3

Options: ``--tasks`` (hdr,hyperspectral,depth), ``--parts`` (3), ``--images`` (8), ``--size`` (256),
``--minutes`` (10), ``--steps N``, ``--supersample`` (2), ``--work`` (out/bench/measured_pair), ``--results``
(benchmarks/results).

Writes RESULTS/measured_pair.md (one row per part and a mean per task) and RESULTS/measured_pair.json (every
metric of every row, each part's errors and PSF checksum, the settings and the seconds each step took). The
scenes are the validation split's (no test-split read); the fine-tune's own validation uses the first of them
only to draw its curve (no choice is made from it). Torch runs evaluations on one thread.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_json, atomic_write_text  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SEED = 40  # the parts' seed (none of the splits' PART_SEEDS)
STEPS = ("told nominal", "told measured", "fine-tuned")


def measured_parts(task: str, n: int, supersample: int, seed: int = SEED) -> list[tuple[dict, object]]:
    """``n`` parts of ``task``'s committed design drawn from the shipped budget: (their errors, their PSF pair at
    the network's bands, planes and window, computed on the design grid refined ``supersample``×)."""
    import torch

    from doefab.optics.psf import PSFPair
    from doefab.reconstruction.specs import design_dir, network_kernel
    from doefab.tolerance.errors import load_budget, sample_errors
    from doefab.tolerance.judge import PSFJudge

    budget = load_budget()
    judge = PSFJudge(design_dir(task), supersample)
    d = judge.design
    kernel = network_kernel(task, d.task_params.get("kernel_size"))
    out = []
    for child in np.random.SeedSequence([seed, ("hdr", "hyperspectral", "depth").index(task)]).spawn(n):
        err = sample_errors(budget, np.random.default_rng(child), seed=int(child.generate_state(1)[0]),
                            n_masks=judge.n_masks)
        err = replace(err, crosstalk=(0.0, 0.0))  # crosstalk acts on the captures (the conditions), not the PSF
        with torch.no_grad():
            got = judge.psfs(err, halves=("coded", "uncoded"), kernel=kernel)
        out.append((err.to_json(), PSFPair(got["coded"].float(), got["uncoded"].float(), tuple(d.wavelengths),
                                           tuple(d.depths), d.camera.sensor_pitch,
                                           provenance={"source": "simulation", "supersample": supersample})))
    return out


def _sha(pair) -> str:
    h = hashlib.sha256()
    for t in (pair.coded, pair.uncoded):
        h.update(t.contiguous().numpy().tobytes())
    return h.hexdigest()


def one_part(task: str, pair, work: Path, args) -> dict:
    """The three steps' metrics on one part's captures, and the fine-tune's summary."""
    from doefab.reconstruction.evaluate import evaluate
    from doefab.reconstruction.partfinetune import finetune_on_pair
    from doefab.tolerance.conditions import measured

    if work.exists():
        shutil.rmtree(work)  # this script's own folder of an earlier run
    cond = {s: measured(pair, s) for s in ("train", "val")}
    kw = dict(images=args.images, size=args.size, variants=("proposed",), conditions=cond["val"], split="val",
              progress=False)
    rows, seconds = {}, {}
    t = time.perf_counter()
    rows[STEPS[0]] = evaluate(task, work / "a", **kw)["rows"]["proposed"]
    rows[STEPS[1]] = evaluate(task, work / "b", psf=pair, **kw)["rows"]["proposed"]
    seconds["evaluate"] = round((time.perf_counter() - t) / 2, 1)
    t = time.perf_counter()
    ft = finetune_on_pair(task, pair, work / "ft", args.minutes, conditions=cond, max_steps=args.steps,
                          command="benchmarks/measured_pair.py")
    seconds["finetune"] = round(time.perf_counter() - t, 1)
    rows[STEPS[2]] = evaluate(task, work / "c", weights_dir=work / "ft" / "weights", psf=pair, **kw)["rows"]["proposed"]
    return {"rows": rows, "finetune": ft, "seconds": seconds}


def table(result: dict) -> str:
    """The Markdown page: one row per part, a mean per task."""
    s = result["settings"]
    lines = ["# A part's own PSF pair: what each step buys its networks\n",
             f"`.venv/bin/python benchmarks/measured_pair.py {s['command']}`: {s['parts']} part(s) per task drawn "
             f"from the shipped budget, their PSFs on a {s['supersample']}× finer grid (the measurement), "
             f"{s['images']} validation scenes of {s['size_px']}² px captured through each with the budget's "
             f"crosstalk; the shipped proposed network told the nominal pair, told the measured pair, and told it "
             f"after a network-only fine-tune of {s['minutes']} min"
             + (f" (at most {s['steps']} steps)" if s["steps"] else "") + f" on it. Run on {s['machine']}\n",
             "| task | part | metric | " + " | ".join(STEPS) + " | fine-tune steps |",
             "| --- | --- | --- | " + " | ".join("---" for _ in STEPS) + " | --- |"]
    for task, got in result["tasks"].items():
        m = got["metric"]
        unit = " (dB)" if m == "psnr" else " (m)"
        for i, part in enumerate(got["parts"]):
            vals = " | ".join(f"{part['rows'][k][m]:.4g}" for k in STEPS)
            lines.append(f"| {task} | {i + 1} | {m}{unit} | {vals} | {part['finetune']['steps']} |")
        means = " | ".join(f"**{np.mean([p['rows'][k][m] for p in got['parts']]):.4g}**" for k in STEPS)
        lines.append(f"| {task} | mean | {m}{unit} | {means} | |")
    better = "Higher PSNR is better; lower MAE is better."
    return "\n".join(lines) + f"\n\n{better} Every metric of every row, each part's errors and the seconds each " \
                              f"step took: `measured_pair.json`.\n"


def main(argv=None) -> int:
    import os
    import platform

    from doefab.reconstruction.specs import get_spec

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", default="hdr,hyperspectral,depth")
    ap.add_argument("--parts", type=int, default=3)
    ap.add_argument("--images", type=int, default=8)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--supersample", type=int, default=2)
    ap.add_argument("--work", default="out/bench/measured_pair")
    ap.add_argument("--results", default=str(RESULTS))
    args = ap.parse_args(argv)
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]
    for t in tasks:
        get_spec(t)
    result = {"settings": {"command": " ".join(argv if argv is not None else sys.argv[1:]), "parts": args.parts,
                           "images": args.images, "size_px": args.size, "minutes": args.minutes, "steps": args.steps,
                           "supersample": args.supersample, "split": "val", "seed": SEED,
                           "machine": f"{platform.machine()}, {os.cpu_count()} CPU threads."}, "tasks": {}}
    for task in tasks:
        t = time.perf_counter()
        parts = measured_parts(task, args.parts, args.supersample)
        psf_s = round((time.perf_counter() - t) / max(len(parts), 1), 1)
        got = {"metric": get_spec(task).metric, "seconds_per_part_psf": psf_s, "parts": []}
        for i, (err, pair) in enumerate(parts):
            print(f"{task}: part {i + 1} of {len(parts)}", flush=True)
            row = one_part(task, pair, Path(args.work) / task / f"part{i + 1}", args)
            got["parts"].append({"errors": err, "psf_sha256": _sha(pair), **row})
        result["tasks"][task] = got
    out = Path(args.results)
    atomic_write_json(out / "measured_pair.json", json.loads(json.dumps(result, default=str)))
    atomic_write_text(out / "measured_pair.md", table(result))
    print(f"wrote {out / 'measured_pair.md'} and {out / 'measured_pair.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
