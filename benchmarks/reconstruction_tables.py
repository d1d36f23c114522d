"""The paper's Tables 1–3 on the held-out test split, from `doefab evaluate` outputs, as Markdown: each variant
under honest captures (fabricated parts, crosstalk unmixed by a noisy calibration, depth between the network's
planes; the network told the nominal PSF) beside the nominal model's own captures (`--clean`), and hyperspectral
results for in-library and out-of-library light.

Run: .venv/bin/python benchmarks/reconstruction_tables.py out/s14/eval out/s15/eval out/s13/eval
(each ROOT holds <task>/metrics.json and <task>_clean/metrics.json, as scripts/train_shipped.sh writes; a task is
taken from the first ROOT that has it); writes benchmarks/results/reconstruction_tables.md. Split used: test
(once, for these tables).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

OUT = Path(__file__).parent / "results"
KEYS = {"hdr": ("psnr", "psnr_highlight", "rmse_highlight"), "hyperspectral": ("psnr", "ssim", "sam"),
        "depth": ("mae", "rmse", "delta125")}
NAMES = {"rmse": "RMSE", "psnr": "PSNR (dB)", "rmse_highlight": "highlight RMSE", "psnr_highlight":
         "highlight PSNR (dB)", "ssim": "SSIM", "sam": "SAM (rad)", "mae": "MAE (m)", "delta125": "δ<1.25"}


def _load(root: Path, name: str) -> dict | None:
    f = root / name / "metrics.json"
    return json.loads(f.read_text()) if f.is_file() else None


def task_table(task: str, honest: dict, clean: dict | None) -> list[str]:
    keys = KEYS[task]
    head = ["variant"] + [f"{NAMES[k]} honest" for k in keys] + ([f"{NAMES[k]} clean" for k in keys] if clean else [])
    head.append("training steps")
    lines = [f"**{task}**: {honest['images']} held-out test scenes of {honest['size_px']}² px "
             f"({honest['conditions'].get('parts', 0)} fabricated parts)", "",
             "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for v, row in honest["rows"].items():
        cells = [f"{row[k]:.4g}" for k in keys] + ([f"{clean['rows'][v][k]:.4g}" for k in keys] if clean else [])
        lines.append(f"| {v.replace('_', '-')} | " + " | ".join(cells) + f" | {honest['weights'][v]['steps']} |")
    lines += [""] + paired_lines(task, honest)
    if task == "hyperspectral" and honest.get("by_light"):
        lines += light_table(honest, clean)
    return lines + [""]


PRIMARY = {"hdr": ("psnr_highlight", "dB"), "hyperspectral": ("psnr", "dB"), "depth": ("mae", "m")}


def paired_lines(task: str, honest: dict) -> list[str]:
    """The proposed variant against each ablation on the task's primary metric, scene by scene: the mean paired
    difference (positive: proposed better) with its 95 % Student-t interval over the test scenes, overall and,
    for hyperspectral, per kind of light. The scenes share the evaluation's fabricated parts and each network
    is one training run: the interval is over scenes, given those."""
    per = honest.get("per_image", {}).get("rows")
    if not per:
        return []
    key, unit = PRIMARY[task]
    sign = -1.0 if key == "mae" else 1.0  # lower MAE is better
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


def main(roots: list[Path]) -> None:
    lines = []
    for task in KEYS:
        root = next((r for r in roots if _load(r, task) is not None), None)
        if root is not None:
            lines += task_table(task, _load(root, task), _load(root, f"{task}_clean"))
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "reconstruction_tables.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main([Path(a) for a in sys.argv[1:]] or [Path("out/ship10/eval")])
