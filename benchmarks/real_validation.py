"""Every shipped network on the measured-data validation set (split ``real``: HDR radiance maps, measured depth
maps, light of a measured family no split holds; ``doefab.reconstruction.realdata``) beside the synthetic
validation split, both under honest captures (fabricated parts, crosstalk unmixed by a noisy calibration, depth
between the network's planes; the networks told the nominal PSF), torch on one thread.

    .venv/bin/python benchmarks/real_validation.py --images 12 --size 256 --seed-weights out/seeds/s1/weights out/seeds/s2/weights

The seed folders hold each task's proposed network trained as the shipped one but from another seed
(``doefab train --task T --variant proposed --steps N --seed S --weights-dir out/seeds/sS/weights``, N as the
shipped weights record); a task with fewer than three seeds (the shipped one included) has no spread.

Evaluations go to out/real_validation/<task>_<split>/ (an evaluation already there for the same weights is
reused: the run resumes); writes benchmarks/results/real_validation.json (each evaluation's metrics.json) and
real_validation.md (the sources with their licenses, the tables, proposed against each ablation on the real set
scene by scene, and the shipping rule with its decisions, ``shipping_decisions``). Split used: val and real
(validation); the test split is not read (its depth δ<1.25 is quoted from the committed
benchmarks/results/evaluate_depth.json).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from doefab.io import read_json  # noqa: E402
from reconstruction_tables import KEYS, NAMES, paired_lines  # noqa: E402
from shipping_decisions import DECISIONS, RULE  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SPLITS = ("real", "val")


def budget_now() -> str:
    """The digest of the shipped tolerance budget, as honest captures record it (``conditions.budget_sha256``)."""
    from doefab.tolerance.conditions import budget_sha256

    return budget_sha256()


def evaluate_split(task: str, split: str, images: int, size: int, work: Path, weights_dir=None,
                   variants=("proposed", "coded_only", "uncoded_only"), name: str | None = None) -> dict:
    """``task``'s networks (``weights_dir``'s, default the shipped ones) on ``split``, honest captures; an
    evaluation already in ``work`` for the same weights, scenes, size and tolerance budget is reused."""
    from doefab.reconstruction.evaluate import evaluate, one_thread
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.data import real_components
    from doefab.tolerance.conditions import for_splits

    out = work / (name or f"{task}_{split}")
    f = out / "metrics.json"
    if f.is_file():
        done = read_json(f)
        shas = {v: load_reconstructor(task, v, weights_dir).meta["weights_sha256"] for v in variants}
        same_set = split != "real" or done.get("real_sha256") == real_components()
        same_set &= done["conditions"].get("budget_sha256") == budget_now()
        if (done["images"], done["size_px"]) == (images, size) and set(done["weights"]) == set(variants) and all(
                w["sha256"] == shas[v] for v, w in done["weights"].items()) and same_set:
            print(f"{task} {split}: reusing {f}")
            return done
    with one_thread():  # the parts computed on one thread, as the CLI computes them
        cond = for_splits(task, None, "honest", (split,), progress=True)[split]
    return evaluate(task, out, images=images, size=size, conditions=cond, split=split, weights_dir=weights_dir,
                    variants=variants)


def seed_runs(task: str, seed_dirs: list[Path], images: int, size: int, work: Path) -> list[dict]:
    """The proposed network of each seed folder that holds one for ``task``, on the measured set."""
    runs = []
    for d in seed_dirs:
        if (d / f"{task}_proposed.json").is_file():
            runs.append(evaluate_split(task, "real", images, size, work, weights_dir=d, variants=("proposed",),
                                       name=f"{task}_real_" + "_".join(d.resolve().parts[-2:])))
    return runs


# what makes a task's measured scenes: its part of ``data.real_components()`` (the rest is other tasks' data and
# realdata's source, which changes with code that draws no other scene)
SCENE_COMPONENT = {"hdr": "hdr", "hyperspectral": "light", "depth": "depth"}


def _base(real: dict) -> dict:
    """What of a measured-set run the seeds' spread is read against: the shipped proposed network's scores, with
    the code and budget they were made at and the network (its weights' SHA-256 and steps)."""
    w = real.get("weights", {}).get("proposed")
    return {"code": real["code"], "budget_sha256": real["conditions"].get("budget_sha256"),
            **({"weights": {"sha256": w["sha256"], "steps": w["steps"]}} if w else {}),
            "rows": {"proposed": real["rows"]["proposed"]},
            "per_image": {"rows": {"proposed": real["per_image"]["rows"]["proposed"]}}}


def carried_seeds(now: dict, committed: dict | None) -> tuple[list[dict], dict | None]:
    """The committed seed runs of a task, and the shipped network's scores they were measured beside when those are
    not the scores of ``now`` (the same scenes scored at another code or budget; None when every measured scene
    scores as then, to 1e-6): the spread then compares three runs made at one code and budget. Seeds scored on
    other scenes (another count, size or measured set) are refused: their spread is to be measured again."""
    import math

    if not committed or not committed.get("seeds"):
        return [], None
    base = committed.get("seed_base") or _base(committed["real"])
    part = SCENE_COMPONENT[now["real"]["task"]]

    def scenes(run):
        return run["images"], run["size_px"], run["real_sha256"][part]

    if any(scenes(r) != scenes(now["real"]) for r in committed["seeds"]):
        raise SystemExit(f"{now['real']['task']}: the committed seeds were scored on other measured scenes than "
                         "this run's (count, size or data): score the seeds' weights again with --seed-weights")
    a, b = now["real"]["per_image"]["rows"]["proposed"], base["per_image"]["rows"]["proposed"]
    same = len(a) == len(b) and all(set(x) == set(y) and all(math.isclose(x[k], y[k], rel_tol=1e-6) for k in x)
                                    for x, y in zip(a, b))
    return committed["seeds"], (None if same else base)


def seed_values(run: dict, seeds: list[dict], key: str) -> list[float]:
    """The proposed network's ``key`` on the measured set for the shipped seed (its ``seed_base`` score when the
    seeds were scored beside that) and each other seed: the values the spread is the SD of."""
    base = run.get("seed_base") or run["real"]
    return [base["rows"]["proposed"][key]] + [r["rows"]["proposed"][key] for r in seeds]


def spread_lines(runs: dict, seeds: dict) -> list[str]:
    """Run-to-run spread of each task's primary metric on the measured set: the shipped proposed network and the
    same training from other seeds, all scored at one code and budget (a task's ``seed_base`` when its seeds were
    scored before the shipped network's current scores)."""
    import numpy as np

    from doefab.applications import APPLICATIONS

    lines = ["Run-to-run spread of the proposed network's primary metric on the measured set, over training seeds "
             "(seed 0 is the network shipped when they were scored; the other seeds were trained with `doefab train "
             "--task T --variant "
             "proposed --steps N --seed S` at this code, the shipped ones at the code their weights record):", "",
             "| task | metric | seed 0 (shipped when the seeds were scored) | other seeds | mean | SD over seeds |",
             "| --- | --- | --- | --- | --- | --- |"]
    notes = []
    for task in KEYS:
        others = seeds.get(task)
        if not others:
            continue
        key = APPLICATIONS[task].primary_metric
        base = runs[task].get("seed_base")
        vals = seed_values(runs[task], others, key)
        if len(vals) < 3:
            continue  # the rule's spread needs three seeds at least
        lines.append(f"| {task} | {NAMES[key]} | {vals[0]:.4g} | {', '.join(f'{v:.4g}' for v in vals[1:])} | "
                     f"{np.mean(vals):.4g} | {np.std(vals, ddof=1):.3g} |")
        now = runs[task]["real"].get("weights", {}).get("proposed", {})
        if base and base.get("weights", {}).get("sha256", now.get("sha256")) != now.get("sha256"):
            notes.append(f"The {task} seeds are those of the network shipped before this one (weights "
                         f"{base['weights']['sha256'][:12]}, {base['weights']['steps']} steps; its own score "
                         f"{vals[0]:.4g} in the row, at {base['code']}): the spread of its recipe, which the decision "
                         f"to ship the present network ({now['steps']} steps, {now['sha256'][:12]}, "
                         f"{runs[task]['real']['rows']['proposed'][key]:.4g} in the table above) was read against; "
                         f"the present recipe's own spread over seeds is not measured.")
        elif base:
            notes.append(f"The {task} seeds were scored at {base['code']} under the budget {base['budget_sha256']}, "
                         f"beside the shipped network's {vals[0]:.4g} in the same run; at the table's code and budget "
                         f"({runs[task]['real']['conditions'].get('budget_sha256')}) the shipped network scores "
                         f"{runs[task]['real']['rows']['proposed'][key]:.4g} (the table above).")
    if len(lines) == 4:
        return ["No task has three seeds of its proposed network on the measured set yet: the spread, and so the "
                "rule, is not measured.", ""]
    return lines + [""] + ([" ".join(notes), ""] if notes else [])


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
    if task == "hdr":
        peaks = hdr_peaks(real["images"], real["size_px"])
        lines += ["Peak radiance of each measured HDR scene (the half-exposure capture clips at 2, the scenes are "
                  "capped at 2^8): " + ", ".join(f"{p:.3g}" for p in peaks) + ".", ""]
    if task == "depth" and test_depth is not None:
        d_real, d_test = real["rows"]["proposed"]["delta125"], test_depth["rows"]["proposed"]["delta125"]
        lines += [f"Depth δ<1.25 of the proposed network: {d_real:.3f} on the measured set, {d_test:.3f} on the "
                  f"committed test-split table (benchmarks/results/evaluate_depth.json, scored under its own "
                  f"code's budget; the test split read at later code is in benchmarks/results/"
                  f"depth_error_sources.md): a gap of {d_real - d_test:+.3f}."] + gap_lines(real, test_depth) + [""]
    return lines


def depth_sources(images: int) -> list[str]:
    """The measured scene each of the measured set's first ``images`` depth scenes is a crop of."""
    from doefab.reconstruction.data import sample_rng
    from doefab.reconstruction.realdata import depth_scenes, drawn_depth_scene

    names = [s[0] for s in depth_scenes()]
    return [names[drawn_depth_scene(sample_rng("real", i))] for i in range(images)]


GAP_DRAWS = 20000  # bootstrap draws of the depth gap


def per_scene_delta(run: dict) -> list[float]:
    """The proposed network's δ<1.25 on each scene of an evaluation (none when it keeps no per-scene values)."""
    return [r["delta125"] for r in run.get("per_image", {}).get("rows", {}).get("proposed", [])]


def gap_draws(real, test, groups=None, draws: int = GAP_DRAWS, seed: int = 0):
    """``draws`` bootstrap values of mean(``real``) − mean(``test``): each resamples the test values one by one and
    the measured ones one by one, or (``groups``: the scene each value's crop comes from) by scene, taking every
    crop of each scene drawn."""
    import numpy as np

    real, test = np.asarray(real, float), np.asarray(test, float)
    groups = np.arange(len(real)) if groups is None else np.asarray(groups)
    members = [np.flatnonzero(groups == g) for g in np.unique(groups)]
    rng = np.random.default_rng(seed)
    gaps = np.empty(draws)
    for b in range(draws):
        picked = np.concatenate([members[j] for j in rng.integers(len(members), size=len(members))])
        gaps[b] = real[picked].mean() - test[rng.integers(len(test), size=len(test))].mean()
    return gaps


def percentile_interval(gaps) -> tuple[float, float]:
    """95 % percentile interval (2.5 and 97.5 % points) of bootstrap draws."""
    import numpy as np

    lo, hi = np.percentile(gaps, [2.5, 97.5])
    return float(lo), float(hi)


def gap_interval(real, test, groups=None, draws: int = GAP_DRAWS, seed: int = 0) -> tuple[float, float]:
    """95 % percentile interval of ``gap_draws``."""
    return percentile_interval(gap_draws(real, test, groups, draws, seed))


def _signed(x: float) -> str:
    """``x`` to two decimals with its sign; 0.00 when it rounds to zero either way."""
    v = round(x, 2)
    return "0.00" if v == 0 else f"{v:+.2f}"


def gap_lines(real: dict, test_depth: dict) -> list[str]:
    """The gap's 95 % intervals over scenes (the measured crops one by one, and by their scene), and where the
    crops come from."""
    from collections import Counter

    per_real, per_test = per_scene_delta(real), per_scene_delta(test_depth)
    if len(per_real) < 2 or len(per_test) < 2:
        return []
    sources = depth_sources(len(per_real))
    counts = Counter(sources)
    each, clustered = gap_interval(per_real, per_test), gap_interval(per_real, per_test, sources)
    return [f"Its 95 % interval over scenes (percentile bootstrap, {GAP_DRAWS} draws of the {len(per_test)} test "
            f"scenes and the {len(per_real)} measured crops one by one): {_signed(each[0])} to {_signed(each[1])}; "
            f"drawing the crops by the scene they are cut from (approximate with {len(counts)} scenes): "
            f"{_signed(clustered[0])} to {_signed(clustered[1])}. The crops come from "
            + ", ".join(f"{n} ×{c}" for n, c in counts.most_common()) + "."]


def hdr_peaks(images: int, size: int) -> list[float]:
    """Peak radiance (× the scene's ordinary exposure; the half-exposure capture clips at 2) of each measured HDR
    scene as the evaluation draws it (the scene with its PSF margin)."""
    from doefab.reconstruction.data import sample_rng
    from doefab.reconstruction.realdata import hdr_real_sample
    from doefab.reconstruction.specs import crop_margin

    big = size + 2 * crop_margin("hdr")
    return [float(hdr_real_sample(sample_rng("real", i), big).max()) for i in range(images)]


def sources_lines() -> list[str]:
    from doefab.reconstruction.realdata import SOURCES

    lines = ["| task | source | what is measured | where | license | used as |", "|" + " --- |" * 6]
    lines += [f"| {s.task} | {s.name} | {s.measured} | {s.origin} | {s.license} | {s.use} |" for s in SOURCES]
    return lines + [""]


def budget_lines(runs: dict) -> list[str]:
    """Which tolerance budgets the table's measured rows were captured under, beside the one doefab ships now."""
    from doefab.tolerance.conditions import budget_sha256

    used = sorted({runs[t]["real"]["conditions"].get("budget_sha256") for t in runs if "real" in runs[t]} - {None})
    now = budget_sha256()
    if used == [now]:
        return [f"Every measured row was captured under the shipped tolerance budget ({now}).", ""]
    return [f"The measured rows were captured under the budget {', '.join(used)}; the shipped budget is now {now} "
            f"(`doefab/tolerance/budget.toml` changed since; the results page says how).", ""]


def markdown(runs: dict, test_depth: dict | None, seeds: dict | None = None, command: str = "", note: str = "") -> str:
    lines = ["# Shipped networks on measured data", "",
             f"Produced by `{command}`.{note}",
             "", "## Sources (none of them in training)", ""] + sources_lines()
    lines += ["## Scores: measured set (real) beside the synthetic validation split (val)", ""]
    for task in KEYS:
        if task in runs:
            lines += task_lines(task, runs[task], test_depth if task == "depth" else None)
    lines += budget_lines(runs)
    lines += ["## Shipping rule", "", RULE, ""] + spread_lines(runs, seeds or {})
    lines += ["| date | task | candidate | compared | decision |",
              "| --- | --- | --- | --- | --- |"] + [f"| {' | '.join(d)} |" for d in DECISIONS] + [""]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--tasks", default=",".join(KEYS))
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "real_validation")
    ap.add_argument("--seed-weights", type=Path, nargs="*", default=[],
                    help="weights folders of the proposed networks trained from other seeds")
    ap.add_argument("--render-only", action="store_true",
                    help="rewrite real_validation.md from the committed real_validation.json; evaluate nothing")
    args = ap.parse_args()
    committed = RESULTS / "real_validation.json"
    before = read_json(committed) if committed.is_file() else {}
    if args.render_only:
        return render_committed(before)
    runs = {t: {s: evaluate_split(t, s, args.images, args.size, args.work) for s in SPLITS}
            for t in args.tasks.split(",")}
    seeds = {}
    for t in runs:
        seeds[t], base = seed_runs(t, args.seed_weights, args.images, args.size, args.work), None
        if not seeds[t]:
            seeds[t], base = carried_seeds(runs[t], before.get(t))
        runs[t]["seeds"] = seeds[t]
        if base:
            runs[t]["seed_base"] = base
    for t in KEYS:  # a task not evaluated keeps its committed evaluations and seeds
        if t not in runs and t in before:
            runs[t], seeds[t] = before[t], before[t].get("seeds", [])
    runs = {t: runs[t] for t in KEYS if t in runs}
    f = RESULTS / "evaluate_depth.json"
    test_depth = read_json(f) if f.is_file() else None
    from doefab.io import atomic_write_json, atomic_write_text

    atomic_write_json(RESULTS / "real_validation.json", runs)
    command = " ".join([".venv/bin/python benchmarks/real_validation.py", "--images", str(args.images), "--size",
                        str(args.size)] + (["--seed-weights", *map(str, args.seed_weights)] if args.seed_weights else []))
    if args.tasks != ",".join(KEYS):
        command += f" --tasks {args.tasks}"
    kept = [t for t in runs if t not in args.tasks.split(",")]
    note = (f" The {' and '.join(kept)} evaluations and seed runs are kept from the file as committed before this run."
            if kept else "")
    atomic_write_text(RESULTS / "real_validation.md", markdown(runs, test_depth, seeds, command, note))
    print(f"wrote {RESULTS / 'real_validation.md'}")


def render_committed(runs: dict) -> None:
    """real_validation.md from the committed evaluations (their command line kept: they are what it produced)."""
    from doefab.errors import DoefabError
    from doefab.io import atomic_write_text

    page, depth = RESULTS / "real_validation.md", RESULTS / "evaluate_depth.json"
    if not runs or not page.is_file() or not depth.is_file():
        raise DoefabError(f"--render-only rewrites {page} from the committed real_validation.json and "
                          f"evaluate_depth.json: run without --render-only to evaluate first")
    produced = page.read_text().split("Produced by `", 1)[1].split("\n", 1)[0]  # `command`.note
    command, note = produced.split("`.", 1)
    seeds = {t: runs[t].get("seeds", []) for t in runs}
    atomic_write_text(page, markdown(runs, read_json(depth), seeds, command, note))
    print(f"wrote {page} from the committed evaluations")


if __name__ == "__main__":
    main()
