"""Each error kind's fabricated-PSF error against the simulation grid, and its run time.

1. Per design and error kind (the grid study every tolerance run makes, ``doefab.tolerance.grid``): the part
   with that error alone at the default budget's value, on a 128² block of the design, on grids 1×, 2×, 4×
   against 8×; the bound on the PSF metric's error scaled to the whole design (the block's own beside it) and
   the seconds per part on the block.
2. The committed grating design at full size: the PSF metric of each rigid and mask-level error at 1× and 2×,
   the seconds per part (the 2× grid is a 3200² pupil), and whether the 1×−2× difference lies within the grid
   study's bound for 1×.
Writes benchmarks/results/tolerance_grid.{md,json}. Run: .venv/bin/python benchmarks/tolerance_grid.py
(``--designs grating --block-only --out DIR``: the grating's grid study alone, a check that it runs).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

OUT = Path(__file__).parent / "results"
FULL_KINDS = ("decenter across split", "mount rotation", "mask overlay", "edge bias")
DESIGNS = ("streak", "grating", "half-ring")


def block_tables(budget, designs=DESIGNS) -> tuple[list[str], dict]:
    from doefab.tolerance.grid import grid_study
    from doefab.tolerance.judge import PSFJudge

    rows = ["| design | error | budget value | bound 1× | bound 2× | bound 4× | the block's own 1× | "
            "its effect (8×) | s/part 1× | s/part 8× | grid chosen |", "|" + " --- |" * 11]
    data = {}
    for name in designs:
        g = grid_study(PSFJudge(f"masks/{name}/design", 1), budget)
        data[name] = g
        for k, v in g["kinds"].items():
            b = v["bound"]
            rows.append(f"| {name} | {k} | {v['value']:.3g} {v['unit']} | {b[1]:.2g} | {b[2]:.2g} | {b[4]:.2g} | "
                        f"{v['block_bound'][1]:.2g} | {v['effect_bound']:.2g} | {v['seconds'][1]:.2f} | "
                        f"{v['seconds'][8]:.2f} | {v['grid']}× |")
            print(rows[-1], flush=True)
    return rows, data


def full_grating(budget, study: dict) -> tuple[list[str], dict]:
    from doefab.tolerance.judge import PSFJudge
    from doefab.tolerance.kinds import kind

    res = {}
    for s in (1, 2):
        j = PSFJudge("masks/grating/design", s)
        res[s] = {"nominal": (j.score(j.nominal)["metric"], j.seconds_per_psf)}
        for name in FULL_KINDS:
            t = time.perf_counter()
            m = j.evaluate(kind(name).budget_part(budget, j.n_masks))["metric"]
            res[s][name] = (m, time.perf_counter() - t)
            print(s, name, res[s][name], flush=True)
        del j
    rows = ["| error (default budget value) | PSF metric 1× | PSF metric 2× | 1× − 2× | "
            "grid study's bound for 1× | s/part 1× | s/part 2× |", "|" + " --- |" * 7]
    for name in ("nominal", *FULL_KINDS):
        (m1, t1), (m2, t2) = res[1][name], res[2][name]
        b = study["kinds"].get(name, {}).get("bound", {}).get(1)
        within = "exact on any grid" if b is None else f"{b:.2g} ({'covers' if abs(m1 - m2) <= b else 'EXCEEDED'})"
        rows.append(f"| {name} | {m1:.4f} | {m2:.4f} | {m1 - m2:+.4f} | {within} | {t1:.1f} | {t2:.1f} |")
    return rows, res


def main(argv=None):
    import argparse

    from doefab.tolerance.errors import load_budget

    ap = argparse.ArgumentParser(description="each error kind's PSF-metric error against the simulation grid")
    ap.add_argument("--designs", nargs="+", choices=DESIGNS, default=DESIGNS, help="committed designs to study")
    ap.add_argument("--block-only", action="store_true", help="skip the full-size grating at 1× and 2× (minutes)")
    ap.add_argument("--out", type=Path, default=OUT, help="folder for tolerance_grid.{md,json}")
    args = ap.parse_args(argv)
    budget = load_budget()
    b_rows, b_data = block_tables(budget, args.designs)
    full = not args.block_only and "grating" in b_data
    f_rows, f_data = full_grating(budget, b_data["grating"]) if full else ([], {})
    scales = "; ".join(f"{n} {min(g['block_to_full']):.1f}–{max(g['block_to_full']):.1f}×" for n, g in b_data.items()
                       if "block_to_full" in g)
    text = ["Grid study on a 128² block of each committed design (default budget; bound on the PSF metric's error "
            "against the 8× grid, scaled to the whole design by the ratio of the light its metric pixels hold to the "
            f"block's, per band: {scales}; the block's own bound beside it):", "", *b_rows, "",
            *(["Committed grating design at full size (1600² at 1×, 3200² at 2×; 31 bands):", "", *f_rows] if full
              else [])]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "tolerance_grid.md").write_text("\n".join(text) + "\n")
    (args.out / "tolerance_grid.json").write_text(json.dumps({"block": b_data, "full_grating": f_data}, indent=1,
                                                        default=str) + "\n")
    print("\n".join(text))


if __name__ == "__main__":
    main()
