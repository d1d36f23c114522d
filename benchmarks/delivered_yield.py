"""Delivered-quality yield of the committed designs, and the scene noise on it against the part-to-part spread.

Each part drawn from the shipped budget is judged through its task's proposed network on the reconstruction
tables' test scenes, rendered as ``doefab evaluate`` renders them (``doefab.tolerance.netjudge``); its delivered
value is the mean over those scenes. Per design the script writes the PSF-level yield (Wilson interval) beside
the delivered-quality yield and mean with their two-level (parts, then scenes) bootstrap intervals
(``doefab.tolerance.delivered``), and the variance components of the primary delivered metric: the part-to-part
spread, the scene noise on one part's value, the F test of whether the parts differ at all, the scene set's offset
common to all parts and the fewest scenes per part that put the scene noise below the spread (a point estimate).

The published numbers (hours on 2 cores: each part is 8 scenes of 256² px through the network, depth parts also
their PSFs at 65 planes; nothing else on the machine):
    .venv/bin/python benchmarks/delivered_yield.py --parts 24 --scenes 8 --size 256
(the grating's parts take about 11 GB each: on a 23 GB machine judge it alone with ``--workers 1``; each part is
seeded, so the worker count changes its numbers only by the float rounding of its PSFs' thread count)
More scenes per part measure the components better (they do not depend on the count), e.g.
    .venv/bin/python benchmarks/delivered_yield.py --parts 12 --scenes 16 --size 256 --name delivered_scene_noise
The intervals of a committed run, restated with this code's statistics from its stored components:
    .venv/bin/python benchmarks/delivered_yield.py --restate --name delivered_yield_streak
A toy run that checks the script (its numbers mean nothing; measured on 2 shared cores: streak 790 s, grating
552 s, half-ring 522 s):
    .venv/bin/python benchmarks/delivered_yield.py --parts 3 --scenes 2 --size 64 --grid 1 --out /tmp/delivered_toy

Writes OUT/NAME.md and OUT/NAME.json (default benchmarks/results/delivered_yield.*); the parts' samples go to
WORK/DESIGN-… (default out/delivered; resumed when rerun with the same settings).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DESIGNS = ("streak", "grating", "half-ring")


def judge_design(design: str, parts: int, networks: dict, grid, seed: int, work: Path, workers=None) -> dict:
    """One design's PSF-level and delivered-quality yields, means and variance components."""
    from doefab.tolerance.delivered import delivered_summary
    from doefab.tolerance.errors import PartErrors, load_budget
    from doefab.tolerance.montecarlo import monte_carlo
    from doefab.tolerance.yieldstats import summarize
    from doefab.tolerance.spec import TASK_OF_DESIGN
    from doefab.tolerance.study import evaluate_part, judge_for

    ddir = ROOT / "masks" / design / "design"
    budget = load_budget()
    task, spec = TASK_OF_DESIGN[design], budget.get("spec", {})
    if grid == "auto":
        from doefab.tolerance.grid import grid_study

        grid = grid_study(judge_for(str(ddir), 1), budget, progress=True)["monte_carlo_grid"]
    t = time.perf_counter()
    nominal = evaluate_part(str(ddir), 1, PartErrors().to_json(), networks)
    folder = work / f"{design}-{networks['images']}x{networks['size']}px-grid{grid}-seed{seed}"
    rows = monte_carlo(ddir, budget, parts, folder, seed=seed, supersample=int(grid), networks=networks,
                       workers=workers)
    s = summarize(rows, spec, task, {"psf": {"psf_metric": nominal["metric"]}, "network": nominal["network"]})
    return {"design": design, "task": task, "grid": int(grid), "parts": parts, "judge": networks,
            "seconds": round(time.perf_counter() - t, 1), "nominal": {k: nominal[k] for k in ("metric", "network")},
            "psf_yield": s["yield"], "network": s["network"],
            "delivered": delivered_summary(rows, nominal["network_scenes"], spec, task, seed)}


def restate(path: Path) -> list[dict]:
    """The records of a committed run with the statistics this code derives from them: the mean's t interval over
    parts and scenes and the parts' F test (``doefab.tolerance.delivered``), from the mean squares the run's
    variance components give back (a component the run clipped at 0 is taken at its largest value, the
    interaction's, which widens the interval; the parts' F test is then unknown, None); the bootstrap's interval
    kept beside it as ``bootstrap_mean_ci95``."""
    from doefab.tolerance.delivered import crossed_mean_stats, mean_interval

    results = json.loads(path.read_text())
    for r in results:
        for d in r["delivered"].values():
            c = d["components"]
            p, s, rest = c["parts"], c["scenes"], c["interaction_sd"] ** 2
            c.update(crossed_mean_stats(s * c["part_sd"] ** 2 + rest, p * c["scene_sd"] ** 2 + rest, rest, p, s))
            if c["part_sd"] == 0:  # the parts' mean square is unknown below the interaction's: p is only bounded
                c["parts_differ_p"] = None
            d.setdefault("bootstrap_mean_ci95", d["mean_ci95"])
            d["mean_ci95"] = mean_interval(d["mean"], c)
    return results


def _restate(stem: Path) -> None:
    md = stem.with_suffix(".md").read_text().splitlines()
    command = md[0].split("`")[1]
    results = restate(stem.with_suffix(".json"))
    table = markdown(results, command)
    ends = next(i for i in range(3, len(md)) if not md[i].startswith("|"))  # the old table's end
    kept = md[ends + 3:]  # the text after the table's own caption line
    stem.with_suffix(".json").write_text(json.dumps(results, indent=1, default=str))
    stem.with_suffix(".md").write_text("\n".join(table + ([""] + kept if kept else [])) + "\n")
    print("\n".join(table))


def _p_text(p) -> str:
    return "—" if p is None else f"{p:.3f}"


def markdown(results: list[dict], command: str) -> list[str]:
    from doefab.reconstruction.metrics import DISPLAY, metric_text

    lines = [f"Delivered-quality yield of the committed designs under the shipped budget (`{command}`): each part "
             "through its task's proposed network told the nominal PSF, on the reconstruction tables' test scenes; "
             "intervals over parts and scenes (the mean's: Student's t of the crossed design; the yield's: two-level "
             "bootstrap joined with the parts' Wilson interval).", "",
             "| design | PSF-level yield (Wilson 95 %) | delivered metric: error-free part | mean of the parts (95 %) | "
             "delivered-quality yield (95 %) | part-to-part spread | scene noise on a part | parts differ (F test p) | "
             "common scene offset | scenes needed | wall time (s) |", "|" + " --- |" * 11]
    for r in results:
        d, y = r["delivered"]["nominal_psf"], r["psf_yield"]
        task, m, c = r["task"], r["delivered"]["nominal_psf"]["metric"], d["components"]
        name = DISPLAY[task][m][0]
        lines.append(
            f"| {r['design']} | {y['value']:.2f} ({y['ci95'][0]:.2f}–{y['ci95'][1]:.2f}) | {name} "
            f"{metric_text(task, m, r['nominal']['network']['nominal_psf'][m])} | {metric_text(task, m, d['mean'])} "
            f"({metric_text(task, m, d['mean_ci95'][0], unit=False)}–{metric_text(task, m, d['mean_ci95'][1])}) | "
            + (f"{d['yield']:.2f} ({d['yield_ci95'][0]:.2f}–{d['yield_ci95'][1]:.2f})" if d["yield"] is not None
               else "no limit") + f" | {metric_text(task, m, c['part_sd'])} | {metric_text(task, m, c['part_noise_sd'])} "
            f"({c['scenes']} scenes) | {_p_text(c.get('parts_differ_p'))} | {metric_text(task, m, c['common_noise_sd'])} | "
            f"{c['scenes_needed'] or '— (no spread)'} | {r['seconds']:.0f} |")
    j = results[0]["judge"]
    lines += ["", f"{results[0]['parts']} parts per design, each on {j['images']} {j['split']} scenes of {j['size']}² "
                  f"px. Scene noise on a part: the part × scene interaction over √scenes; scenes needed: the fewest "
                  f"that put it below the part-to-part spread (a point estimate; where the F test's p exceeds 0.05 "
                  f"these scenes do not resolve the spread, and the count has no upper bound)."]
    return lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("designs", nargs="*", default=list(DESIGNS))
    p.add_argument("--parts", type=int, default=24, help="Monte Carlo parts per design")
    p.add_argument("--scenes", type=int, default=8, help="test scenes each part is judged on")
    p.add_argument("--size", type=int, default=256, help="scene side in px (a multiple of 32, at least 64)")
    p.add_argument("--grid", default="auto", help="simulation grid: auto (the grid study's) or an integer")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    p.add_argument("--name", default="delivered_yield")
    p.add_argument("--workers", default="auto", help="worker processes (auto: one per core; the grating's parts need "
                   "about 11 GB each, so on a 23 GB machine: 1)")
    p.add_argument("--work", type=Path, default=ROOT / "out" / "delivered", help="the parts' samples (resumed)")
    p.add_argument("--restate", action="store_true", help="judge nothing: rewrite OUT/NAME.{json,md} with the "
                   "statistics this code derives from the run's stored variance components (the text after the "
                   "table is kept)")
    a = p.parse_args()
    if a.restate:
        return _restate(a.out / a.name)
    from doefab.tolerance.netjudge import judge_settings

    networks = judge_settings({"images": a.scenes, "size": a.size, "split": "test"})  # refuses a bad value first
    grid = a.grid if a.grid == "auto" else int(a.grid)
    workers = None if a.workers == "auto" else int(a.workers)  # None: monte_carlo's own choice
    results = [judge_design(d, a.parts, networks, grid, a.seed, a.work, workers) for d in a.designs]
    named = "" if list(a.designs) == list(DESIGNS) else " ".join(a.designs) + " "
    command = (f".venv/bin/python benchmarks/delivered_yield.py {named}--parts {a.parts} --scenes {a.scenes} "
               f"--size {a.size}"
               + ("" if a.grid == "auto" else f" --grid {a.grid}")
               + ("" if a.workers == "auto" else f" --workers {a.workers}")
               + ("" if a.name == "delivered_yield" else f" --name {a.name}"))
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / f"{a.name}.json").write_text(json.dumps(results, indent=1, default=str))
    (a.out / f"{a.name}.md").write_text("\n".join(markdown(results, command)) + "\n")
    print("\n".join(markdown(results, command)))


if __name__ == "__main__":
    main()
