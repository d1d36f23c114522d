"""Depth training recipes against the shipped proposed depth network, on validation data only: the measured-data
validation set (split ``real``: nine Middlebury 2014 scenes' measured depth) and the synthetic validation split, both
under honest captures (six fabricated parts per split, crosstalk unmixed by a noisy calibration, depth between the
network's planes), 12 scenes of 256² px, torch on one thread; and each network's read of a fronto-parallel wall at
1–5 m behind the validation split's three photographs (``WALL_PHOTOS``; framed as ``depth_planes`` frames its
own, whose photographs include test ones). Each
candidate is a weights folder made by ``doefab train --task depth --variant proposed`` with its recipe, named on the
command line; its validation curve (the run folder's history.csv, validation MAE every 50 steps on 8 scenes of
128² px) is printed beside it, to show whether the run had reached its plateau.

    .venv/bin/python benchmarks/depth_recipes.py "1000 steps=out/recipes/A" "1000 steps, room layouts=out/recipes/B"

Each NAME=FOLDER: the folder holds depth_proposed.{pt,json} and history.csv (``--out`` and the weights in one
folder). The shipped network is scored in the same run. Writes benchmarks/results/depth_recipes.{md,json}; no test
content is read. ``--walls-only NAME=FOLDER …`` reads the walls again for the committed runs of those names.
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

RESULTS = ROOT / "benchmarks" / "results"
# what each candidate named on the command line was (the weights records name the command and code)
RECIPES = {"1000 steps": "the shipped network's recipe (honest captures, 128-px crops, batch 4, Adam with a cosine "
                         "decay from 1e-3, seed 0) for 1000 steps instead of 500, at git 8bce273",
           "1000 steps, room layouts": "the same, with half the training scenes drawn as rooms and streets "
                                       "(slanted and curved surfaces, backgrounds anywhere in the range, objects "
                                       "evenly in inverse depth: `depthlayouts` of git 28d013e, taken out again in "
                                       "a5e87bc)"}
WALLS = (1.0, 1.25, 1.5, 2.0, 3.0, 4.0, 5.0)
WALL_PHOTOS = ("immunohistochemistry", "gravel", "stereo_motorcycle")  # data.IMAGES["val"], checked in main
SPLITS = ("real", "val")


def _wall_photo(image, side: int):
    """A validation photograph (linear radiance, ``data.split_images``) resized to ``side``² and scaled to
    0.05–0.9, as ``depth_planes`` scales its photographs."""
    import numpy as np
    from skimage import transform

    im = transform.resize(image, (side, side), anti_aliasing=True)
    return (0.05 + 0.85 * im / max(float(im.max()), 1e-6)).astype(np.float32).transpose(2, 0, 1)


def wall_reads(weights_dir) -> dict:
    """{wall depth (m): [read per photograph]} of ``weights_dir``'s proposed depth network (None: the shipped) behind
    the validation split's photographs (``WALL_PHOTOS``)."""
    import numpy as np
    import torch

    import depth_planes as dp
    import doefab
    from doefab.reconstruction.data import split_images

    torch.set_num_threads(1)
    rec = doefab.load_reconstructor("depth", weights_dir=weights_dir)
    margin = rec.pair.coded.shape[-1] // 2
    side = dp.SIZE + 2 * margin
    reads: dict = {}
    for image in split_images("val"):
        scene = _wall_photo(image, side)
        for z in WALLS:
            depth = np.full((side, side), z, np.float32)
            reads.setdefault(f"{z:g}", []).append(dp._read(rec, scene, rec.pair, margin, depth))
    return reads


def curve(folder: Path | None) -> list[tuple[int, float]]:
    """(step, validation MAE in m) at each validation of a run folder's history.csv (None: the shipped network's,
    as its weights keep it; [] without one)."""
    f = ROOT / "doefab" / "weights" / "depth_proposed_history.csv" if folder is None else folder / "history.csv"
    if not f.is_file():
        return []
    out = []
    with f.open() as fh:
        for row in csv.DictReader(fh):
            v = float(row["val_mae"])
            if v == v and (not out or out[-1][1] != v):
                out.append((int(row["step"]), v))
    return out


def measure(candidates: dict, images: int, size: int, work: Path) -> dict:
    from doefab.reconstruction.evaluate import evaluate, one_thread
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.tolerance.conditions import for_splits

    with one_thread():  # the parts computed on one thread, as the CLI computes them
        cond = for_splits("depth", None, "honest", SPLITS, progress=True)
    res = {}
    for name, folder in {"shipped": None, **candidates}.items():
        meta = load_reconstructor("depth", weights_dir=folder).meta
        entry = {"weights_sha256": meta["weights_sha256"], "steps": meta["training"]["steps"],
                 "command": meta["training"]["command"], "code": meta["training"].get("code"), "curve": curve(folder)}
        for split in SPLITS:
            tag = name.replace(" ", "_").replace(",", "")
            r = evaluate("depth", work / f"{tag}_{split}", images=images, size=size, conditions=cond[split],
                         split=split, weights_dir=folder, variants=("proposed",), progress=False)
            entry[split] = {k: r["rows"]["proposed"][k] for k in ("mae", "rmse", "delta125")}
            entry["eval_code"] = r["code"]
            print(name, split, entry[split], flush=True)
        entry["walls_m"] = wall_reads(folder)
        res[name] = entry
    return {"images": images, "size_px": size, "runs": res}


def markdown(res: dict, command: str) -> str:
    import numpy as np

    lines = ["# Depth training recipes on validation data", "",
             f"`{command}`: each proposed depth network on {res['images']} scenes of {res['size_px']}² px of the "
             "measured set (real) and of the synthetic validation split, honest captures (6 fabricated parts per "
             "split), torch on one thread; and its median read of a wall behind the validation split's photographs ("
             + ", ".join(WALL_PHOTOS) + "; framed as `depth_planes.py` frames its own, one thread). No test "
             "content is read.", "",
             "| network | steps | MAE real (m) | δ<1.25 real | MAE val (m) | δ<1.25 val | "
             + " | ".join(f"wall {z:g} m" for z in WALLS) + " |", "| --- " * (6 + len(WALLS)) + "|"]
    for name, e in res["runs"].items():
        walls = " | ".join(f"{float(np.median(e['walls_m'][f'{z:g}'])):.2f}" for z in WALLS)
        lines.append(f"| {name} | {e['steps']} | {e['real']['mae']:.3f} | {e['real']['delta125']:.3f} | "
                     f"{e['val']['mae']:.3f} | {e['val']['delta125']:.3f} | {walls} |")
    if res.get("walls_command"):
        lines += ["", f"The walls were read again behind the validation photographs by `{res['walls_command']}`."]
    lines += [""] + [f"- {n}: {RECIPES[n]}." for n in res["runs"] if n in RECIPES]
    lines += ["", "Validation MAE (m) during each run (8 scenes of 128² px, every 50 steps):", ""]
    for name, e in res["runs"].items():
        if e["curve"]:
            lines.append(f"- {name}: " + ", ".join(f"{s}: {v:.3f}" for s, v in e["curve"]))
    lines += ["", "Weights: " + "; ".join(f"{n} {e['weights_sha256'][:12]} (`{e['command']}`)"
                                         for n, e in res["runs"].items()), ""]
    return "\n".join(lines)


def main() -> None:
    from doefab.io import atomic_write_json, atomic_write_text

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("candidates", nargs="*", help="NAME=FOLDER: a weights folder and its run's history.csv")
    ap.add_argument("--tables-only", action="store_true", help="depth_recipes.md again from the committed JSON")
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "depth_recipes")
    ap.add_argument("--walls-only", action="store_true",
                    help="read the walls again for the committed runs named NAME=FOLDER, nothing else")
    args = ap.parse_args()
    from doefab.reconstruction.data import IMAGES

    assert tuple(IMAGES["val"]) == WALL_PHOTOS, "the wall photographs are the validation split's"
    if args.tables_only or args.walls_only:
        res = json.loads((RESULTS / "depth_recipes.json").read_text())
        for item in args.candidates if args.walls_only else ():
            name, _, folder = item.partition("=")
            res["runs"][name]["walls_m"] = wall_reads(Path(folder))
            res["walls_command"] = ".venv/bin/python benchmarks/depth_recipes.py --walls-only " + " ".join(
                f'"{c}"' for c in args.candidates)
        atomic_write_json(RESULTS / "depth_recipes.json", res)
        atomic_write_text(RESULTS / "depth_recipes.md", markdown(res, res["command"]))
        return
    candidates = {}
    for item in args.candidates:
        name, _, folder = item.partition("=")
        if not folder or not (Path(folder) / "depth_proposed.json").is_file():
            ap.error(f"{item!r}: give NAME=FOLDER, FOLDER holding depth_proposed.json")
        candidates[name] = Path(folder)
    res = measure(candidates, args.images, args.size, args.work)
    command = ".venv/bin/python benchmarks/depth_recipes.py " + " ".join(f'"{c}"' for c in args.candidates)
    res["command"] = command
    atomic_write_json(RESULTS / "depth_recipes.json", res)
    atomic_write_text(RESULTS / "depth_recipes.md", markdown(res, command))
    print(markdown(res, command))


if __name__ == "__main__":
    main()
