"""How often the diagnosis's 2σ intervals hold the truth: parts drawn from the shipped tolerance budget
(``tolerance.errors.sample_errors``: every error it draws, mask rotations and roughness included), their PSF pairs
computed on a grid ``--supersample``× finer than the fit's design grid and recorded with photon noise
(``--photons`` detected photons per half, band and plane, Poisson), each diagnosed (``doefab.lab.diagnose``) as
``doefab diagnose`` does, torch on one thread. The published numbers (about 20 minutes on 2 cores):

    .venv/bin/python benchmarks/diagnose_coverage.py --block 64 --parts 20

Options: ``--design DIR`` (default masks/streak/design), ``--block N``, ``--parts``, ``--starts`` (diagnose's),
``--photons`` (1e6), ``--supersample`` (2), ``--seed`` (41), ``--results DIR`` (benchmarks/results),
``--roughness-nm R`` (the parts' surface roughness, RMS; default the budget's: ``0`` shows how much of the
shortfall the roughness that the fit holds makes).

``--block N``: instead of the whole design, an N-pixel block of it where all its masks have edges (its coded
half's outer part), the right half plain, on a 20 mm sensor distance and a kernel of N − 1 pixels (the test's
configuration: seconds per fit); the budget's decenter is scaled to the block's aperture as the holder's 0.25 mm
is to the design's. Without it, the whole design (on a CPU, hours per part).

Writes RESULTS/diagnose_coverage.md (per error: parts where the diagnosis identified it, the fraction of those
whose truth lies within the stated 2σ, the median |error| over σ; the identified etch depth scales' largest
error; the fit's median run time) and RESULTS/diagnose_coverage.json (every part's truth, fit, σ and flags, the
settings, the machine's CPU count).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path

# numpy's BLAS on one thread too: a multi-threaded OpenBLAS sums in another order from run to run, and a fit's path
# (its local minimum, the parts it computes) follows the last bits; set before numpy loads it
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_json, atomic_write_text  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parents[1]


def block(design_dir: Path, n: int, out: Path) -> Path:
    """An ``n``-pixel block of the design (see the module docstring), saved to ``out``; returns its folder."""
    import doefab
    from doefab.design.design import Design

    full = Design.load(design_dir)
    big = full.camera.doe_pixels
    lv = np.ascontiguousarray(full.levels[(big - n) // 2:(big + n) // 2, big // 8:big // 8 + n]).copy()
    lv[:, n // 2:] = full.n_levels - 1
    cam = dataclasses.replace(full.camera, doe_pixels=n, aperture_diameter=n * full.camera.doe_pitch,
                              sensor_distance=20e-3)
    k = n - 1
    d = Design(task=full.task, task_params={**full.task_params, "kernel_size": k, "arm_px": k // 3}, camera=cam,
               wavelengths=full.wavelengths, depths=full.depths, height=doefab.levels_to_height(lv, cam), levels=lv,
               metrics={"name": full.metrics.get("name", "task metric")}, n_levels=full.n_levels)
    d.save(out)
    return out


def one_part(design_dir: Path, budget: dict, err, args, seed: int) -> dict:
    """One part recorded and diagnosed: per error its truth, fit, σ, identifiable and z = (fit − truth) / σ."""
    import torch

    import doefab
    from doefab.design.design import Design
    from doefab.fabrication.levels import levels_sha256
    from doefab.lab.diagnose import diagnose
    from doefab.lab.diagreport import deviations
    from doefab.tolerance.judge import PSFJudge

    d = Design.load(design_dir)
    with torch.no_grad():
        got = PSFJudge(d, args.supersample).psfs(err, halves=("coded", "uncoded"))
    rng = np.random.default_rng(seed)

    def noisy(p):
        p = p.double().numpy()
        s = p.sum(axis=(-1, -2), keepdims=True)
        return torch.from_numpy(rng.poisson(p / s * args.photons) / args.photons * s)
    pair = doefab.PSFPair(noisy(got["coded"]), noisy(got["uncoded"]), d.wavelengths, d.depths, d.camera.sensor_pitch,
                          provenance={"levels_sha256": levels_sha256(d.levels)})
    t = time.perf_counter()
    diag = diagnose(pair, design_dir, budget, starts=args.starts, seed=seed)
    seconds = time.perf_counter() - t
    truth = deviations(err, len(diag["errors"]["etch_depth_scale"]))
    rows = []
    for r in diag["against_budget"]:
        if r["error"] not in truth:
            continue
        s = r["sigma"]
        z = None if not s else (r["value"] - truth[r["error"]]) / s
        rows.append({"error": r["error"], "unit": r["unit"], "truth": truth[r["error"]], "fit": r["value"], "sigma": s,
                     "identifiable": r["identifiable"], "z": z})
    return {"seconds": seconds, "parts_computed": diag["fit"]["parts"], "rows": rows, "actions": diag["actions"],
            "errors": err.to_json()}


def summary(parts: list[dict]) -> dict:
    """Per error: identified count, 2σ coverage, median |z|; the etch scales' largest error; the median run time."""
    names = [r["error"] for r in parts[0]["rows"]]
    per = {}
    for name in names:
        rs = [r for p in parts for r in p["rows"] if r["error"] == name and r["identifiable"] and r["z"] is not None]
        per[name] = {"identified": len(rs), "coverage_2sigma": float(np.mean([abs(r["z"]) <= 2 for r in rs])) if rs
                     else None, "median_abs_z": float(np.median([abs(r["z"]) for r in rs])) if rs else None}
    ident = [r for p in parts for r in p["rows"] if r["identifiable"] and r["z"] is not None]
    etch = [abs(r["fit"] - r["truth"]) for r in ident if r["error"].startswith("etch")]
    return {"per_error": per, "coverage_2sigma_all": float(np.mean([abs(r["z"]) <= 2 for r in ident])) if ident
            else None, "identified_rows": len(ident), "etch_scale_max_error_percent": max(etch) if etch else None,
            "median_seconds": float(np.median([p["seconds"] for p in parts])),
            "median_parts_computed": float(np.median([p["parts_computed"] for p in parts]))}


def table(result: dict) -> str:
    s, a = result["summary"], result["settings"]
    design = Path(a["design"]).resolve()
    shown = design.relative_to(ROOT).as_posix() if design.is_relative_to(ROOT) else design.name
    where = f"a {a['block']}-pixel block of {shown}" if a["block"] else shown
    rough = "" if a.get("roughness_nm") is None else f" (their surface roughness {a['roughness_nm']:g} nm RMS)"
    lines = ["# Diagnosis coverage on parts of known errors\n",
             f"`.venv/bin/python benchmarks/diagnose_coverage.py {a['argv']}`: {a['parts']} parts of {where} drawn "
             f"from the shipped budget{rough}, recorded at {a['supersample']}× the fit's grid with {a['photons']:.3g} "
             f"photons per PSF, {a['starts']} starts per fit, {_threads(a)} ({a['cpus']} CPU cores).\n",
             f"- identified errors whose truth lies within the stated 2σ: **{_pct(s['coverage_2sigma_all'])}** of "
             f"{s['identified_rows']}",
             f"- identified etch depth scales: largest error {_num(s['etch_scale_max_error_percent'])} %",
             f"- fit run time: median {s['median_seconds']:.0f} s ({s['median_parts_computed']:.0f} parts computed)\n",
             "| error | parts identified | within 2σ | median \\|fit − truth\\| / σ |", "| --- | --- | --- | --- |"]
    for name, v in s["per_error"].items():
        lines.append(f"| {name} | {v['identified']} / {a['parts']} | {_pct(v['coverage_2sigma'])} | "
                     f"{_num(v['median_abs_z'])} |")
    return "\n".join(lines) + "\n"


def _threads(settings: dict) -> str:
    """How many threads the published run's fits used (runs before numpy's BLAS was pinned: torch only)."""
    blas = settings.get("blas_threads")
    return "torch on one thread" if blas is None else f"torch and numpy's BLAS on {blas} thread{'s' * (blas != 1)}"


def _pct(v) -> str:
    return "—" if v is None else f"{100 * v:.0f} %"


def _num(v) -> str:
    return "—" if v is None else f"{v:.2g}"


def main(argv=None) -> int:
    from doefab.tolerance.errors import load_budget, sample_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--design", default=str(ROOT / "masks" / "streak" / "design"))
    ap.add_argument("--block", type=int, default=0, help="an N-pixel block of the design (0: the whole design)")
    ap.add_argument("--parts", type=int, default=20)
    ap.add_argument("--starts", type=int, default=None, help="default: doefab.lab.diagnose.STARTS")
    ap.add_argument("--photons", type=float, default=1e6)
    ap.add_argument("--supersample", type=int, default=2)
    ap.add_argument("--seed", type=int, default=41)
    ap.add_argument("--results", default=str(RESULTS))
    ap.add_argument("--roughness-nm", type=float, default=None, help="the parts' RMS roughness (default: budget's)")
    args = ap.parse_args(argv)
    if args.roughness_nm is not None and not args.roughness_nm >= 0:
        ap.error(f"--roughness-nm must be 0 or more (nm RMS), got {args.roughness_nm}")
    if args.starts is None:
        from doefab.lab.diagnose import STARTS

        args.starts = STARTS
    import torch

    torch.set_num_threads(1)  # the fits' times comparable from machine to machine (the published run: one thread)
    budget = load_budget()
    with tempfile.TemporaryDirectory() as tmp:
        design = Path(args.design)
        if args.block:
            full = design
            design = block(design, args.block, Path(tmp) / "design")
            from doefab.design.design import Design

            scale = Design.load(design).camera.aperture_diameter / Design.load(full).camera.aperture_diameter
            budget["mounting"] = {**budget["mounting"],
                                  "decenter_max_mm": budget["mounting"]["decenter_max_mm"] * scale}
        from doefab.design.design import Design
        from doefab.fabrication.process import mask_count

        n_masks = mask_count(Design.load(design).n_levels)
        parts = []
        for i, child in enumerate(np.random.SeedSequence(args.seed).spawn(args.parts)):
            err = sample_errors(budget, np.random.default_rng(child), seed=i, n_masks=n_masks)
            err = dataclasses.replace(err, crosstalk=(0.0, 0.0))  # each half is recorded with the other blocked
            if args.roughness_nm is not None:
                err = dataclasses.replace(err, roughness=args.roughness_nm * 1e-9)
            parts.append(one_part(design, budget, err, args, seed=args.seed + i))
            print(f"part {i + 1}/{args.parts}: {parts[-1]['seconds']:.0f} s", flush=True)
    settings = {**vars(args), "argv": " ".join(argv if argv is not None else sys.argv[1:]), "cpus": os.cpu_count(),
                "blas_threads": int(os.environ["OPENBLAS_NUM_THREADS"])}
    result = {"settings": settings, "summary": summary(parts), "parts": parts}
    out = Path(args.results)
    atomic_write_json(out / "diagnose_coverage.json", json.loads(json.dumps(result, default=str)))
    atomic_write_text(out / "diagnose_coverage.md", table(result))
    print(table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
