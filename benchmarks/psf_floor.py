"""The 31-band coded PSF against its own floor: the FFTs and matrix products it cannot avoid, timed in the same run.

Case (as ``psf_error_vs_time.py``): the hyperspectral preset (1600² DOE grid at 5.4 µm), a 16-level blazed
grating of period 16 DOE pixels, point in focus, 31 bands 400–700 nm, coded half, K = 512 sensor pixels, the
spectral route in float32. Timed, medians of ``--repeats`` runs on ``--threads`` torch threads:

- ``PSFPlan(...)(height)``: what a user's first call costs (the plan's per-band pixel matrices built);
- a second call on the same plan (matrices cached: what a design iteration costs);
- the floor: per band, the route's own work on tensors of the same shapes and dtype — the zero-padded 2-D FFT
  of the pupil, |·|², and the two real matrix products ``W_y · I · W_xᵀ`` — with nothing else.

``--baseline REV`` (default HEAD) measures the same in the same run with the package as of git revision REV
(checked out into a temporary worktree), for a before-and-after table; ``--baseline none`` skips it.

Writes benchmarks/results/psf_floor.{md,json}. Run: .venv/bin/python benchmarks/psf_floor.py --baseline REV
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np
import torch
from revisions import add_arguments, code_root, measure_at, median_time  # this folder is on the path of a script run

sys.path.insert(0, code_root())  # the package measured (a baseline's worktree)
import doefab  # noqa: E402

def floor_work(plan, half: str = "coded"):
    """A function doing, per band, only the spectral route's FFT, |·|² and two matrix products on tensors of
    the plan's shapes (random pupil values: the work does not depend on them)."""
    setup, prepared = plan._prepared(half, True)
    geo = plan._halves[half][0]
    (ly, lx), mats = prepared
    g = torch.Generator().manual_seed(0)
    shape = (1, len(geo.y), len(geo.x))
    pupil = torch.polar(torch.ones(shape), torch.rand(shape, generator=g) * 6.28)

    def run():
        for wy, wxt, _ in mats:
            field = torch.fft.fft2(pupil, s=(ly, lx))
            re_im = torch.view_as_real(field)
            inten = torch.addcmul(re_im[..., 0] * re_im[..., 0], re_im[..., 1], re_im[..., 1])
            wy @ inten @ wxt
    return run, {"pupil": list(shape[1:]), "fft": [ly, lx], "kernel": int(mats[0][0].shape[0])}


def measure(args) -> dict:
    """{"sizes", "seconds": {first_call, plan_reused, floor}} with the package on ``sys.path``."""
    torch.set_num_threads(args.threads)
    cam = doefab.Camera.preset("hyperspectral")
    lams = np.linspace(400e-9, 700e-9, args.bands)
    h = doefab.blazed_grating_height(cam, 16, n_levels=16)

    def plan():
        return doefab.PSFPlan(cam, lams, [cam.focus_distance], args.kernel, halves=("coded",))
    warm = plan()
    warm(h)
    first = median_time(lambda: plan()(h), args.repeats)
    again = median_time(lambda: warm(h), args.repeats)
    fn, sizes = floor_work(warm)
    return {"sizes": sizes, "seconds": {"first_call": first, "plan_reused": again,
                                        "floor": median_time(fn, args.repeats)}}


def baseline(rev: str, args) -> dict:
    """``measure`` in a subprocess with the package as of git revision ``rev`` (a temporary worktree)."""
    sha, got = measure_at(rev, __file__, ["--bands", str(args.bands), "--kernel", str(args.kernel), "--repeats",
                                          str(args.repeats), "--threads", str(args.threads)])
    return {"revision": sha, **got}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bands", type=int, default=31)
    ap.add_argument("--kernel", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=9)
    add_arguments(ap)
    args = ap.parse_args(argv)
    if args.measure_only:
        print(json.dumps(measure(args)))
        return 0
    from doefab.io import atomic_write_json, atomic_write_text

    before = None if args.baseline == "none" else baseline(args.baseline, args)
    now = measure(args)
    result = {"settings": {**vars(args), "torch": torch.__version__, "cpus": os.cpu_count()}, "sizes": now["sizes"],
              "seconds": now["seconds"], "baseline": before}
    out = Path(args.results)
    atomic_write_json(out / "psf_floor.json", result)
    atomic_write_text(out / "psf_floor.md", table(result))
    print(table(result))
    return 0


def table(r: dict) -> str:
    a, z = r["settings"], r["sizes"]
    before = r.get("baseline")
    rev = before["revision"] if before else "none"  # the revision measured, not the name given
    runs = ([(f"previous code ({rev})", before["seconds"])] if before else []) + [("this code", r["seconds"])]
    lines = [
        f"`.venv/bin/python benchmarks/psf_floor.py --baseline {rev}`: the {a['bands']}-band coded PSF of "
        f"the hyperspectral preset (pupil {z['pupil'][0]} × {z['pupil'][1]} samples, FFT {z['fft'][0]} × "
        f"{z['fft'][1]}, K = {z['kernel']}), spectral route, float32, torch {a['torch']} on {a['threads']} threads, "
        f"medians of {a['repeats']} runs, each code's floor measured in its own run.",
        "",
        "| code | floor: per band one padded FFT, \\|·\\|², two matrix products (s) | a new plan, "
        "`PSFPlan(...)(height)` (s) | × floor | the same plan called again (s) | × floor |",
        "| --- | --- | --- | --- | --- | --- |"]
    for name, s in runs:
        lines.append(f"| {name} | {s['floor']:.2f} | {s['first_call']:.2f} | {s['first_call'] / s['floor']:.2f} | "
                     f"{s['plan_reused']:.2f} | {s['plan_reused'] / s['floor']:.2f} |")
    return "\n".join(lines + [""])


if __name__ == "__main__":
    raise SystemExit(main())
