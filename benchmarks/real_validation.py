"""Every shipped network on the measured-data validation set (split ``real``: HDR radiance maps, a measured depth
map, light of a measured family no split holds; ``doefab.reconstruction.realdata``) beside the synthetic
validation split, both under honest captures (fabricated parts, crosstalk unmixed by a noisy calibration, depth
between the network's planes; the networks told the nominal PSF), torch on one thread.

    .venv/bin/python benchmarks/real_validation.py --images 12 --size 256

Evaluations go to out/real_validation/<task>_<split>/ (an evaluation already there for the same weights is
reused: the run resumes); writes benchmarks/results/real_validation.json (each evaluation's metrics.json) and
real_validation.md (the sources with their licenses, the tables, proposed against each ablation on the real set
scene by scene, and the shipping rule with its decisions, ``DECISIONS``). Split used: val and real (validation);
the test split is not read (its depth δ<1.25 is quoted from the committed benchmarks/results/evaluate_depth.json).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from reconstruction_tables import KEYS, NAMES, paired_lines  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SPLITS = ("real", "val")
RULE = ("A network, or a change to how networks are trained, ships only if on the measured-data validation set "
        "(split real, honest captures) its task's primary metric is no worse than the shipped network's by more "
        "than the run-to-run spread of that metric over training seeds; the spread is measured over at least three "
        "seeds of the same training and recorded here with the decision.")
# each decision: (date, task, candidate, what was compared, outcome)
DECISIONS = (
    ("2026-11-27", "all", "the shipped networks (trained before the measured set existed)",
     "first score on the measured set: the baseline each later candidate is compared with", "kept (baseline)"),
)


def evaluate_split(task: str, split: str, images: int, size: int, work: Path) -> dict:
    from doefab.reconstruction.evaluate import evaluate
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.tolerance.conditions import for_splits

    out = work / f"{task}_{split}"
    f = out / "metrics.json"
    if f.is_file():
        done = json.loads(f.read_text())
        shipped = {v: load_reconstructor(task, v).meta["weights_sha256"] for v in done["weights"]}
        if (done["images"], done["size_px"]) == (images, size) and all(
                w["sha256"] == shipped[v] for v, w in done["weights"].items()):
            print(f"{task} {split}: reusing {f}")
            return done
    cond = for_splits(task, None, "honest", (split,), progress=True)[split]
    return evaluate(task, out, images=images, size=size, conditions=cond, split=split)


def task_lines(task: str, runs: dict, test_depth: dict | None) -> list[str]:
    keys = KEYS[task] + (("sam",) if task == "hyperspectral" else ())
    keys = tuple(dict.fromkeys(keys))
    real, val = runs["real"], runs["val"]
    head = ["variant"] + [f"{NAMES[k]} real" for k in keys] + [f"{NAMES[k]} val" for k in keys]
    lines = [f"**{task}**: {real['images']} scenes of each split, {real['size_px']}² px, honest captures "
             f"({real['conditions'].get('parts', 0)} fabricated parts per split); torch on {real['threads']} thread",
             "", "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for v in real["rows"]:
        cells = [f"{real['rows'][v][k]:.4g}" for k in keys] + [f"{val['rows'][v][k]:.4g}" for k in keys]
        lines.append(f"| {v.replace('_', '-')} | " + " | ".join(cells) + " |")
    lines += ["", "On the measured set (split real):", ""] + paired_lines(task, real)[2:]
    if task == "depth" and test_depth is not None:
        d_real, d_test = real["rows"]["proposed"]["delta125"], test_depth["rows"]["proposed"]["delta125"]
        lines += [f"Depth δ<1.25 of the proposed network: {d_real:.3f} on the measured set, {d_test:.3f} on the "
                  f"committed test-split table (benchmarks/results/evaluate_depth.json): a gap of "
                  f"{d_real - d_test:+.3f}.", ""]
    return lines


def sources_lines() -> list[str]:
    from doefab.reconstruction.realdata import SOURCES

    lines = ["| task | source | what is measured | where | license | used as |", "|" + " --- |" * 6]
    lines += [f"| {s.task} | {s.name} | {s.measured} | {s.origin} | {s.license} | {s.use} |" for s in SOURCES]
    return lines + [""]


def markdown(runs: dict, test_depth: dict | None) -> str:
    lines = ["# Shipped networks on measured data", "",
             "Produced by `.venv/bin/python benchmarks/real_validation.py --images "
             f"{next(iter(runs.values()))['real']['images']} --size {next(iter(runs.values()))['real']['size_px']}`.",
             "", "## Sources (none of them in training)", ""] + sources_lines()
    lines += ["## Scores: measured set (real) beside the synthetic validation split (val)", ""]
    for task in KEYS:
        if task in runs:
            lines += task_lines(task, runs[task], test_depth if task == "depth" else None)
    lines += ["## Shipping rule", "", RULE, "", "| date | task | candidate | compared | decision |",
              "| --- | --- | --- | --- | --- |"] + [f"| {' | '.join(d)} |" for d in DECISIONS] + [""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--tasks", default=",".join(KEYS))
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "real_validation")
    args = ap.parse_args()
    runs = {t: {s: evaluate_split(t, s, args.images, args.size, args.work) for s in SPLITS}
            for t in args.tasks.split(",")}
    f = RESULTS / "evaluate_depth.json"
    test_depth = json.loads(f.read_text()) if f.is_file() else None
    from doefab.io import atomic_write_json, atomic_write_text

    atomic_write_json(RESULTS / "real_validation.json", runs)
    atomic_write_text(RESULTS / "real_validation.md", markdown(runs, test_depth))
    print(f"wrote {RESULTS / 'real_validation.md'}")


if __name__ == "__main__":
    main()
