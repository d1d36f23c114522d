"""The paper's Tables 1–3 on the held-out test split, from `doefab evaluate` outputs, as Markdown: each variant
under honest captures (fabricated parts, crosstalk unmixed by a noisy calibration, depth between the network's
planes; the network told the nominal PSF) beside the nominal model's own captures (`--clean`), and hyperspectral
results for in-library and out-of-library light; each table names its split, thread count, library versions and
the weights' SHA-256.

Run: .venv/bin/python benchmarks/reconstruction_tables.py out/tables/eval
(each ROOT holds <task>/metrics.json and <task>_clean/metrics.json, as scripts/train_shipped.sh writes, or
`doefab evaluate --task TASK --images 12 --size 256 --out ROOT/TASK` and the same with `--clean --out
ROOT/TASK_clean` for the shipped weights; a task is taken from the first ROOT that has it). Copies them to
benchmarks/results/evaluate_<task>.json and evaluate_<task>_clean.json, then writes
benchmarks/results/reconstruction_tables.md from those files alone (a task no ROOT holds keeps its committed
files), so the tables are the JSON's numbers to their printed digits (tests/docs/test_results_consistency.py).
Split used: test. Every evaluation of it is a read of the test split: add its row to
benchmarks/results/test_split_reads.md.

The final test set: `.venv/bin/python benchmarks/reconstruction_tables.py --final ROOT` takes ROOT/<task> and
ROOT/<task>_clean made by `doefab evaluate ... --split final` (each evaluation logs its read in its folder's
final_split_reads.md), copies them to evaluate_final_<task>.json and evaluate_final_<task>_clean.json, writes
reconstruction_tables_final.md from those, and appends the evaluations' logged reads to
benchmarks/results/final_split_reads.md (the set is read once: tests/docs/test_results_consistency.py checks
that the ledger holds one honest and one clean read per task and that the published files are those reads).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.applications import APPLICATIONS  # noqa: E402
from doefab.io import read_json  # noqa: E402
from doefab.reconstruction.evaluate import FINAL_LEDGER  # noqa: E402  (the file each final read is logged in)

OUT = Path(__file__).parent / "results"
KEYS = {"hdr": ("psnr", "psnr_highlight", "rmse_highlight"), "hyperspectral": ("psnr", "ssim", "sam"),
        "depth": ("mae", "rmse", "delta125")}
NAMES = {"rmse": "RMSE", "psnr": "PSNR (dB)", "rmse_highlight": "highlight RMSE", "psnr_highlight":
         "highlight PSNR (dB)", "ssim": "SSIM", "sam": "SAM (rad)", "mae": "MAE (m)", "delta125": "δ<1.25"}


def _load(root: Path, name: str) -> dict | None:
    f = root / name / "metrics.json"
    return read_json(f) if f.is_file() else None


def task_table(task: str, honest: dict, clean: dict | None) -> list[str]:
    keys = KEYS[task]
    head = ["variant"] + [f"{NAMES[k]} honest" for k in keys] + ([f"{NAMES[k]} clean" for k in keys] if clean else [])
    head += ["training steps", "weights SHA-256"]
    versions = ", ".join(f"{k} {v}" for k, v in honest["versions"].items())
    lines = [f"**{task}**: {honest['images']} held-out scenes of the {honest['split']} split, {honest['size_px']}² px "
             f"({honest['conditions'].get('parts', 0)} fabricated parts); torch on {honest['threads']} thread; "
             f"{versions}", "",
             "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for v, row in honest["rows"].items():
        cells = [f"{row[k]:.4g}" for k in keys] + ([f"{clean['rows'][v][k]:.4g}" for k in keys] if clean else [])
        w = honest["weights"][v]
        lines.append(f"| {v.replace('_', '-')} | " + " | ".join(cells) + f" | {w['steps']} | {w['sha256'][:12]} |")
    lines += [""] + paired_lines(task, honest)
    if task == "hyperspectral" and honest.get("by_light"):
        lines += light_table(honest, clean)
    return lines + [""]


PRIMARY = {a.name: (a.primary_metric, a.primary_unit) for a in APPLICATIONS.values()}


def paired_lines(task: str, honest: dict) -> list[str]:
    """The proposed variant against each ablation on the task's primary metric, scene by scene: the mean paired
    difference (positive: proposed better) with its 95 % Student-t interval over the test scenes, overall and,
    for hyperspectral, per kind of light. The scenes share the evaluation's fabricated parts and each network
    is one training run: the interval is over scenes, given those."""
    per = honest.get("per_image", {}).get("rows")
    if not per:
        return []
    key, unit = PRIMARY[task]
    sign = 1.0 if APPLICATIONS[task].higher_is_better else -1.0
    lights = honest["per_image"].get("light")
    groups = [("all scenes", None)] + ([("in-library light", "in-library"), ("out-of-library light",
                                                                           "out-of-library")] if lights else [])
    lines = [f"Proposed better than each ablation by ({NAMES[key]}, scene by scene, honest captures; mean and 95 % "
             f"t-interval over scenes, given the evaluation's {honest['conditions'].get('parts', 0)} fabricated parts "
             f"and one training run per network):", ""]
    for label, light in groups:
        for v in ("coded_only", "uncoded_only"):
            lines.append(f"- {label}, against {v.replace('_', '-')}: " + _paired(per, v, key, sign, unit, lights, light))
    return lines + [""]


def _paired(per: dict, v: str, key: str, sign: float, unit: str, lights, light) -> str:
    import numpy as np
    from scipy import stats

    pick = [i for i in range(len(per["proposed"])) if light is None or lights[i] == light]
    d = sign * np.array([per["proposed"][i][key] - per[v][i][key] for i in pick], float)
    d = d[np.isfinite(d)]
    if len(d) < 2:
        return "n/a (fewer than two scenes)"
    half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
    return (f"{d.mean():+.3g} {unit} ({d.mean() - half:+.3g} to {d.mean() + half:+.3g}); proposed better on "
            f"{int((d > 0).sum())} of {len(d)} scenes")


def light_table(honest: dict, clean: dict | None) -> list[str]:
    """Hyperspectral by the scene's light, honest and clean captures."""
    lines = ["Hyperspectral by the scene's light (out-of-library: light the proposed network's illuminant library "
             "does not hold):", "",
             "| light | variant | PSNR (dB) honest | SSIM honest | SAM (rad) honest"
             + (" | PSNR (dB) clean | SSIM clean | SAM (rad) clean |" if clean else " |"),
             "| --- | --- | --- | --- | ---" + (" | --- | --- | --- |" if clean else " |")]
    for light, rows in honest["by_light"].items():
        for v, row in rows.items():
            cells = [row["psnr"], row["ssim"], row["sam"]]
            if clean and light in clean.get("by_light", {}):
                c = clean["by_light"][light][v]
                cells += [c["psnr"], c["ssim"], c["sam"]]
            lines.append(f"| {light} | {v.replace('_', '-')} | " + " | ".join(f"{x:.4g}" for x in cells) + " |")
    return lines + [""]


def tables_markdown(folder: Path = OUT, prefix: str = "evaluate_") -> str:
    """The tables from ``folder``'s <prefix><task>.json and <prefix><task>_clean.json (``prefix``
    "evaluate_final_": the final test set's)."""
    lines = []
    for task in KEYS:
        honest, clean = (folder / f"{prefix}{task}.json", folder / f"{prefix}{task}_clean.json")
        if honest.is_file():
            lines += task_table(task, read_json(honest),
                                read_json(clean) if clean.is_file() else None)
    return "\n".join(lines) + "\n"


def _checked(f: Path, honest: Path | None = None, split: str = "test") -> Path:
    """``f``, an evaluation by the current `doefab evaluate` (thread count and weights' SHA-256 recorded; a clean
    one of the same weights and split as ``honest``); else the run stops, naming the fix."""
    ev = read_json(f)
    if "threads" not in ev or any("sha256" not in w for w in ev["weights"].values()):
        sys.exit(f"{f}: made before evaluations recorded their thread count and weights' SHA-256: run doefab "
                 f"evaluate again")
    if honest is None and ev["split"] != split:
        sys.exit(f"{f} evaluates the {ev['split']} split, not the {split} split: "
                 + ("pass --final for the final test set" if ev["split"] == "final" else
                    f"evaluate it again with doefab evaluate --split {split}"))
    if honest is not None:
        other = read_json(honest)
        if ev["split"] != other["split"] or any(w["sha256"] != other["weights"][v]["sha256"]
                                                for v, w in ev["weights"].items()):
            sys.exit(f"{f} evaluates other weights or another split than {honest}: evaluate both again")
    return f


def main(roots: list[Path], final: bool = False) -> None:
    prefix = "evaluate_final_" if final else "evaluate_"
    copies = {}  # every evaluation checked before any file is replaced
    for task in KEYS:
        root = next((r for r in roots if _load(r, task) is not None), None)
        if root is None:
            continue
        honest = copies[f"{prefix}{task}.json"] = _checked(root / task / "metrics.json", split="final" if final
                                                           else "test")
        if (root / f"{task}_clean" / "metrics.json").is_file():
            copies[f"{prefix}{task}_clean.json"] = _checked(root / f"{task}_clean" / "metrics.json", honest)
        elif final:  # a table pairs a read's honest and clean scores: never a new one with an older one
            sys.exit(f"{root / task}: no {task}_clean evaluation beside it: evaluate it with doefab evaluate --task "
                     f"{task} --split final --clean --out {root / (task + '_clean')}")
    if not copies:
        sys.exit(f"no <task>/metrics.json in {', '.join(map(str, roots))}: give the folder doefab evaluate wrote to")
    reads = _logged_reads(copies.values()) if final else []
    for name, f in copies.items():
        shutil.copyfile(f, OUT / name)
    if reads:
        ledger = OUT / FINAL_LEDGER
        ledger.write_text(ledger.read_text() + "".join(r + "\n" for r in reads))
    text = tables_markdown(OUT, prefix)
    (OUT / ("reconstruction_tables_final.md" if final else "reconstruction_tables.md")).write_text(text)
    print(text)


def _logged_reads(files) -> list[str]:
    """The rows each final-set evaluation logged of its read (its folder's final_split_reads.md), not yet in the
    committed ledger; the run stops when an evaluation logged none."""
    have = (OUT / FINAL_LEDGER).read_text()
    rows = []
    for f in files:
        log = f.parent / FINAL_LEDGER
        mine = [r for r in (log.read_text().splitlines() if log.is_file() else []) if r.startswith("| 20")]
        if not mine:
            sys.exit(f"{f.parent}: no logged read of the final test set ({FINAL_LEDGER}): evaluate it with "
                     f"doefab evaluate --split final")
        rows += [r for r in mine if r not in have and r not in rows]
    return rows


if __name__ == "__main__":
    args = sys.argv[1:]
    final = "--final" in args
    main([Path(a) for a in args if a != "--final"] or [Path("out/final" if final else "out/tables/eval")], final=final)
