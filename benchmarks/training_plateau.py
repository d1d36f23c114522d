"""Longer training of the HDR and hyperspectral networks against the shipped ones, on validation data only: the
measured-data validation set (split ``real``) and the synthetic validation split, both under honest captures (six
fabricated parts per split, crosstalk unmixed by a noisy calibration), 12 scenes of 256² px, torch on one thread,
each network scored by ``real_validation.evaluate_split`` as the shipping rule scores it. Each candidate is a
weights folder made by ``doefab train --task T --variant V --steps N``, named on the command line with its run
folder; the run's validation curve (history.csv: validation PSNR every 50 steps on 8 scenes of 96² px) is printed
beside it, to show where it levels off.

    .venv/bin/python benchmarks/training_plateau.py hdr "1000 steps=out/s62/weights:out/s62/train/hdr_proposed"

Each NAME=WEIGHTS:RUN: WEIGHTS holds <task>_<variant>.{pt,json}, RUN the run's history.csv. ``--variant`` (default
proposed) names the network compared. The shipped network is scored by the same code path; an evaluation already
in WORK for the same weights, scenes and tolerance budget is reused (``real_validation.evaluate_split``), and each
split's evaluation records its code. Writes
benchmarks/results/training_plateau_<task>.{md,json} (a variant scored before keeps its rows); no test content
is read.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from real_validation import evaluate_split  # noqa: E402
from reconstruction_tables import KEYS, NAMES  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SPLITS = ("real", "val")
TASKS = ("hdr", "hyperspectral")
PAGES = {"hdr": "training_plateau_hdr.md", "hyperspectral": "training_plateau_hyperspectral.md"}  # each with its .json
SHIPPED = "shipped then"  # the network shipped when the run was made, each candidate's comparison


def curve(task: str, variant: str, run: Path | None) -> list[tuple[int, float]]:
    """(step, validation PSNR in dB) at each validation of a run's history.csv (None: the shipped network's, where
    its weights keep one; [] without one)."""
    f = ROOT / "doefab" / "weights" / f"{task}_{variant}_history.csv" if run is None else run / "history.csv"
    if not f.is_file():
        return []
    out = []
    with f.open() as fh:
        for row in csv.DictReader(fh):
            step, v = int(row["step"]), float(row["val_psnr"])
            if v == v and step % 50 == 0 and (not out or out[-1][0] != step):  # validated every 50 steps
                out.append((step, v))
    return out


def _tag(name: str) -> str:
    """A candidate's name as its evaluations' folder names it."""
    return "".join(c if c.isalnum() else "_" for c in name)


def measure(task: str, variant: str, candidates: dict, images: int, size: int, work: Path) -> dict:
    from doefab.reconstruction.loader import load_reconstructor

    res = {}
    for name, (weights, run) in {"shipped": (None, None), **candidates}.items():
        meta = load_reconstructor(task, variant, weights).meta
        entry = {"weights_sha256": meta["weights_sha256"], "steps": meta["training"]["steps"],
                 "wall_time_s": meta["training"].get("wall_time_s"), "command": meta["training"]["command"],
                 "code": meta["training"].get("code"), "curve": curve(task, variant, run)}
        tag = _tag(name)
        for split in SPLITS:
            r = evaluate_split(task, split, images, size, work, weights_dir=weights, variants=(variant,),
                               name=f"{task}_{variant}_{tag}_{split}")
            entry[split] = {k: r["rows"][variant][k] for k in KEYS[task]}
            entry.setdefault("eval_code", {})[split] = r["code"]
            print(name, split, entry[split], flush=True)
        res[name] = entry
    return {"images": images, "size_px": size, "variant": variant, "runs": res}


def markdown(task: str, by_variant: dict) -> str:
    keys = KEYS[task]
    lines = [f"# Longer training on validation data: {task}", ""]
    for variant, res in by_variant.items():
        lines += [f"`{res['command']}`: the {variant.replace('_', '-')} network, each candidate beside the shipped "
                  f"one, on {res['images']} scenes of {res['size_px']}² px of the measured set (real) and of the "
                  "synthetic validation split, honest captures (6 fabricated parts per split), torch on one thread. "
                  "No test content is read.", "",
                  "| network | steps | training (s) | " + " | ".join(f"{NAMES[k]} {s}" for s in SPLITS for k in keys)
                  + " |", "| --- " * (3 + 2 * len(keys)) + "|"]
        for name, e in res["runs"].items():
            cells = " | ".join(f"{e[s][k]:.4g}" for s in SPLITS for k in keys)
            wall = f"{e['wall_time_s']:.0f}" if e.get("wall_time_s") else "—"
            lines.append(f"| {SHIPPED if name == 'shipped' else name} | {e['steps']} | {wall} | {cells} |")
        lines += ["", "Validation PSNR (dB) during each run (8 scenes of 96² px, every 50 steps):", ""]
        label = {n: SHIPPED if n == "shipped" else n for n in res["runs"]}
        lines += [f"- {label[n]}: " + ", ".join(f"{s}: {v:.2f}" for s, v in e["curve"])
                  for n, e in res["runs"].items() if e["curve"]]
        lines += ["", "Weights: " + "; ".join(f"{label[n]} {e['weights_sha256'][:12]} (`{e['command']}`, code "
                                             f"{e['code'] or 'not recorded'})" for n, e in res["runs"].items()), ""]
    return "\n".join(lines)


def main() -> None:
    from doefab.io import atomic_write_json, atomic_write_text

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("task", choices=TASKS)
    ap.add_argument("candidates", nargs="*", help="NAME=WEIGHTS:RUN: a weights folder and its run folder")
    ap.add_argument("--render-only", action="store_true", help="the .md again from the committed .json")
    ap.add_argument("--variant", default="proposed", choices=("proposed", "coded_only", "uncoded_only"))
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "training_plateau")
    args = ap.parse_args()
    f = (RESULTS / PAGES[args.task]).with_suffix(".json")
    if args.render_only:
        return atomic_write_text(f.with_suffix(".md"), markdown(args.task, json.loads(f.read_text())))
    if not args.candidates:
        ap.error("name at least one candidate NAME=WEIGHTS:RUN")
    candidates = {}
    for item in args.candidates:
        name, _, folders = item.partition("=")
        weights, _, run = folders.partition(":")
        if not weights or not run or not (Path(weights) / f"{args.task}_{args.variant}.json").is_file():
            ap.error(f"{item!r}: give NAME=WEIGHTS:RUN, WEIGHTS holding {args.task}_{args.variant}.json")
        if name == "shipped" or _tag(name) in {_tag(n) for n in candidates} | {"shipped"}:
            ap.error(f"{item!r}: name each candidate once, and not 'shipped' (the shipped network's row)")
        candidates[name] = (Path(weights), Path(run))
    res = measure(args.task, args.variant, candidates, args.images, args.size, args.work)
    res["command"] = (f".venv/bin/python benchmarks/training_plateau.py {args.task} "
                      + (f"--variant {args.variant} " if args.variant != "proposed" else "")
                      + " ".join(f'"{c}"' for c in args.candidates))
    done = json.loads(f.read_text()) if f.is_file() else {}
    done[args.variant] = res
    atomic_write_json(f, done)
    atomic_write_text(f.with_suffix(".md"), markdown(args.task, done))
    print(markdown(args.task, done))


if __name__ == "__main__":
    main()
