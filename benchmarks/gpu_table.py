"""CPU against GPU on one machine: the same workloads with ``device="cpu"`` and ``device="cuda"``.

Workloads (each timed as wall time, the GPU synchronised before the clock stops; medians where repeated):
- ``psf``: the 31-band coded PSF of the hyperspectral preset (1600² pupil at 5.4 µm, a 16-level blazed grating,
  K = 512, spectral route, plan + forward; median of 3 after one warm-up);
- ``design``: ``doefab.optimize("streak", iterations=N)`` (Adam on the design grid, N iterations);
- ``train``: ``max_steps`` training steps of each task's proposed network (``doefab.train``; its own data and
  validation included);
- ``judge``: ``tolerance.montecarlo.monte_carlo(masks/grating, default budget, P, networks=True, workers=1)``: P
  parts, each judged at PSF level and through the hyperspectral network (one process, design grid).

Thread count: torch's intra-op threads are recorded (``torch.get_num_threads()``); the CPU rows use every core of the
machine they run on. Writes ``gpu_table.{md,json}`` into ``--out`` (default benchmarks/results).

Run on a machine with a GPU:
    python benchmarks/gpu_table.py --out "$OUT" [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

OUT = Path(__file__).parent / "results"


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def timed(fn, device: str, repeats: int = 1, warmup: int = 0) -> float:
    for _ in range(warmup):
        fn()
        _sync(device)
    times = []
    for _ in range(repeats):
        _sync(device)
        t = time.perf_counter()
        fn()
        _sync(device)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def psf_case(device: str, bands: int, kernel: int) -> float:
    import doefab

    cam = doefab.Camera.preset("hyperspectral")
    lams = np.linspace(400e-9, 700e-9, bands)
    h = doefab.blazed_grating_height(cam, 16, n_levels=16)

    def run():
        plan = doefab.PSFPlan(cam, lams, [cam.focus_distance], kernel, halves=("coded",), device=device)
        return plan(h).coded

    return timed(run, device, repeats=3, warmup=1)


def design_case(device: str, iterations: int) -> float:
    import doefab

    return timed(lambda: doefab.optimize("streak", iterations=iterations, progress=False, device=device), device)


def train_case(device: str, task: str, steps: int, tmp: Path) -> float:
    from doefab.reconstruction.train import train

    out = tmp / f"train_{task}_{device.replace(':', '')}"
    return timed(lambda: train(task, "proposed", minutes=60, out_dir=out, max_steps=steps, progress=False,
                                      val_every=10 ** 6, device=device), device)


def judge_case(device: str, design: str, parts: int, tmp: Path) -> float:
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.montecarlo import monte_carlo

    out = tmp / f"judge_{design}_{device.replace(':', '')}"
    return timed(lambda: monte_carlo(Path("masks") / design / "design", load_budget(), parts, out, workers=1, progress=False,
                                     networks=True, device=device), device)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--quick", action="store_true", help="small sizes: check the script, not the machine")
    ap.add_argument("--only", nargs="*", default=["psf", "design", "train", "judge"])
    ap.add_argument("--devices", nargs="*", default=["cuda", "cpu"])
    ap.add_argument("--tasks", nargs="*", default=["hdr", "hyperspectral", "depth"], help="networks trained")
    ap.add_argument("--steps", type=int, help="training steps per network (default 100; --quick 2)")
    ap.add_argument("--parts", type=int, help="parts judged through the network (default 30; --quick 1)")
    args = ap.parse_args(argv)
    q = args.quick
    bands, kernel, iters, steps, parts = (5, 64, 2, 2, 1) if q else (31, 512, 10, 100, 30)
    steps, parts = args.steps or steps, args.parts or parts
    data = {"torch": torch.__version__, "threads": torch.get_num_threads(), "cores": os.cpu_count(),
            "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None, "rows": {}}
    cases = []
    if "psf" in args.only:
        cases.append((f"{bands}-band coded PSF, K = {kernel} (median of 3)", lambda d, t: psf_case(d, bands, kernel)))
    if "design" in args.only:
        cases.append((f"streak design, {iters} Adam iterations", lambda d, t: design_case(d, iters)))
    if "train" in args.only:
        for task in args.tasks:
            cases.append((f"{steps} training steps, {task} proposed",
                          lambda d, t, task=task: train_case(d, task, steps, t)))
    if "judge" in args.only:
        cases.append((f"{parts} parts judged through the network, grating",
                       lambda d, t: judge_case(d, "grating", parts, t)))
    with tempfile.TemporaryDirectory() as tmp:
        for label, fn in cases:
            got = data["rows"].setdefault(label, {})
            for dev in args.devices:
                try:
                    got[dev] = fn(dev, Path(tmp))
                except Exception as exc:  # noqa: BLE001 - one failed case must not lose the others' numbers
                    got[dev] = None
                    print(f"{label} on {dev}: FAILED {type(exc).__name__}: {exc}", flush=True)
                print(f"{label} on {dev}: {got[dev]}", flush=True)
                _write(args.out, data)  # after every device: a time limit that stops the script keeps what it had
    print((args.out / "gpu_table.md").read_text())
    return 0


def _write(out: Path, data: dict) -> None:
    head = [f"CPU against GPU on one machine ({data['gpu']}; {data['cores']} CPU cores, torch {data['torch']}, "
            f"{data['threads']} intra-op threads on the CPU rows): `python benchmarks/gpu_table.py`.", "",
            "| workload | CPU (s) | GPU (s) | speed-up |", "| --- | --- | --- | --- |"]
    rows = []
    for label, got in data["rows"].items():
        c, g = got.get("cpu"), got.get("cuda")
        cells = [f"{c:.2f}" if c else "—", f"{g:.2f}" if g else "—", f"{c / g:.1f}×" if c and g else "—"]
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
    out.mkdir(parents=True, exist_ok=True)
    (out / "gpu_table.md").write_text("\n".join(head + rows) + "\n")
    (out / "gpu_table.json").write_text(json.dumps(data, indent=1))


if __name__ == "__main__":
    raise SystemExit(main())
