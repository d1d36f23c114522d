"""The PSF pairs a tolerance study's network passes compute outside its Monte Carlo: the error-free part, each error
kind of the default budget alone at one standard deviation (the tornado's parts, with the base part of a spread
about a nominal value) and the quantization study's height maps, each pair as ``NetworkJudge.rendered_pair`` makes
it for the network judge (both halves at the network's kernel; depth: on the rendering planes), one after another
in one judge, as a study asks for them. The previous code (``--baseline REV``) is timed in the same run, each code in
a fresh process, the two taking turns design by design; each pair's PSFs are compared between the codes bit for
bit (SHA-256 of their bytes). No scene or reconstruction is timed: what a part's captures and networks cost does not
change.

Writes benchmarks/results/pair_reuse.{md,json}. Run with nothing else on the machine:
    .venv/bin/python benchmarks/pair_reuse.py --baseline REV
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path

from revisions import add_arguments, code_root, measure_at, same_code_warning, turns

DESIGNS = ("streak", "grating", "half-ring")


def parts(judge, budget) -> list[tuple[str, object, object]]:
    """(label, PartErrors or None, height map or None) in the order a study asks for them."""
    import numpy as np

    from doefab.fabrication.levels import quantize_levels
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.kinds import KINDS
    from doefab.tolerance.study import continuous_height

    out = [("error-free part", PartErrors(), None)]
    for k in KINDS:
        if k.from_budget(budget) != 0.0:
            out.append((k.name, k.budget_part(budget, judge.n_masks), None))
            if k.base_from_budget is not None:
                out.append((k.name + " (its base part)", k.base_part(budget), None))
    d = judge.design
    height = continuous_height(d)
    h2pi = d.camera.material.height_2pi(d.camera.design_wavelength)
    for n in (None, *sorted((n for n in (2, 4, 8, 16, 32) if n <= d.n_levels), reverse=True)):
        if n is None and height is None:
            continue
        h = np.mod(height, h2pi) if n is None else (
            quantize_levels(d.height if height is None else height, d.camera, n).astype(np.float64) * h2pi / n)
        out.append(("heights: " + ("continuous" if n is None else f"{n} levels"), PartErrors(), h))
    return out


def measure(design: str, threads: int) -> dict:
    sys.path.insert(0, code_root())
    import torch

    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.netjudge import NetworkJudge
    from doefab.tolerance.study import judge_for

    torch.set_num_threads(threads)
    root = Path(code_root())
    judge = NetworkJudge(judge_for(str(root / "masks" / design / "design"), 1))
    rows = []
    for label, err, height in parts(judge.base, load_budget()):
        t = time.perf_counter()
        rendered, _ = judge.rendered_pair(err, height)
        s = time.perf_counter() - t
        digest = hashlib.sha256(rendered.coded.numpy().tobytes() + rendered.uncoded.numpy().tobytes()).hexdigest()
        rows.append({"part": label, "seconds": s, "sha256": digest})
    return {"design": design, "planes": len(rendered.depths), "rows": rows}


def replay(design: str) -> dict:
    """The halves each pair of ``measure``'s sequence computes with this code, found without computing a PSF
    (``MountedPlan.psfs`` returns zeros of its shape and records the halves it was asked for): which pairs share."""
    sys.path.insert(0, code_root())
    import torch

    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.mounted import MountedPlan
    from doefab.tolerance.netjudge import NetworkJudge
    from doefab.tolerance.study import judge_for

    asked = []

    def psfs(self, field, decenter=(0.0, 0.0), gap=0.0, halves=None):
        halves = tuple(halves or self.halves)
        asked.extend(halves)
        shape = (len(self.depths), len(self.wavelengths), self.kernel, self.kernel)
        return {h: torch.zeros(shape) for h in halves}
    MountedPlan.psfs = psfs
    judge = NetworkJudge(judge_for(str(Path(code_root()) / "masks" / design / "design"), 1))
    rows = []
    for label, err, height in parts(judge.base, load_budget()):
        asked.clear()
        judge.rendered_pair(err, height)
        rows.append({"part": label, "computed": list(asked)})
    return {"design": design, "rows": rows}


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(ap)
    ap.add_argument("--design", choices=DESIGNS, help=argparse.SUPPRESS)
    ap.add_argument("--replay", action="store_true", help="only add which halves each pair computes (this code, no "
                    "PSF computed) to the timings in the results folder's pair_reuse.json")
    a = ap.parse_args()
    if a.measure_only:
        print(json.dumps(replay(a.design) if a.replay else measure(a.design, a.threads)))
        return
    out = Path(a.results)
    if a.replay:
        data = json.loads((out / "pair_reuse.json").read_text())
        for name in DESIGNS:
            rev, res = measure_at(None, __file__, ["--design", name, "--replay"])
            data["designs"][name]["replay"] = {"revision": rev, **res}
    else:
        data = {"threads": a.threads, "baseline_arg": a.baseline, "designs": {}}
        for i, name in enumerate(DESIGNS):
            for code in turns(a.baseline, start=i):
                rev, res = measure_at(code, __file__, ["--design", name, "--threads", str(a.threads)])
                data["designs"].setdefault(name, {})["this_code" if code is None else "baseline"] = {
                    "revision": rev, **res}
                print(name, rev, round(sum(r["seconds"] for r in res["rows"]), 1), flush=True)
    write(data, out)


def write(data: dict, out: Path) -> None:
    """pair_reuse.{json,md} in ``out``."""
    runs = data["designs"]["streak"]
    same_code_warning(runs.get("baseline", {}).get("revision"), runs["this_code"]["revision"])
    baseline, threads = data["baseline_arg"], data["threads"]
    replayed = all("replay" in runs for runs in data["designs"].values())
    md = ["# PSF pairs outside the Monte Carlo", "",
          f"`.venv/bin/python benchmarks/pair_reuse.py --baseline {baseline}` ({threads} torch threads): the PSF "
          "pairs of a tolerance study's network passes outside its Monte Carlo (the error-free part, each error kind "
          "alone at one standard deviation of the default budget, the quantization study's height maps), in one "
          "judge, in that order; seconds per pair, the previous code timed in the same run."
          + (" The halves each pair computes with this code, without computing a PSF: `.venv/bin/python "
             f"benchmarks/pair_reuse.py --replay` (at {data['designs']['streak']['replay']['revision']})."
             if replayed else ""), "",
          "| design | part | previous code (s) | this code (s) | the same PSFs bit for bit |"
          + (" halves this code computes |" if replayed else ""),
          "| --- | --- | --- | --- | --- |" + (" --- |" if replayed else "")]
    for name, runs in data["designs"].items():
        new, old = runs["this_code"], runs.get("baseline")
        for j, r in enumerate(new["rows"]):
            o = old["rows"][j] if old else None
            md.append(f"| {name} | {r['part']} | {o['seconds']:.1f} |" if o else f"| {name} | {r['part']} | — |")
            same = "—" if not o else ("yes" if o["sha256"] == r["sha256"] else "NO")
            md[-1] += f" {r['seconds']:.1f} | {same} |"
            if replayed:
                md[-1] += f" {', '.join(runs['replay']['rows'][j]['computed']) or 'none'} |"
        tot_new = sum(r["seconds"] for r in new["rows"])
        tot_old = sum(r["seconds"] for r in old["rows"]) if old else float("nan")
        planes = f"{new['planes']} plane" + ("s" if new["planes"] != 1 else "")
        md.append(f"| {name} | **all {len(new['rows'])} pairs** ({planes}; previous code "
                  f"{old['revision'] if old else '—'}, this code {new['revision']}) | **{tot_old:.0f}** | "
                  f"**{tot_new:.0f}** | |" + (" |" if replayed else ""))
    out.mkdir(parents=True, exist_ok=True)
    (out / "pair_reuse.json").write_text(json.dumps(data, indent=1) + "\n")
    (out / "pair_reuse.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
