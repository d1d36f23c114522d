"""The seed's Tables 1–3 on the held-out test split, from `doefab evaluate` outputs, as Markdown: each variant
under honest captures (fabricated parts, crosstalk unmixed by a noisy calibration, depth between the network's
planes; the network told the nominal PSF) beside the nominal model's own captures (`--clean`), and hyperspectral
results for in-library and out-of-library light.

Run: .venv/bin/python benchmarks/reconstruction_tables.py out/ship9/eval
(expects <root>/<task>/metrics.json and <root>/<task>_clean/metrics.json, as scripts/train_shipped.sh writes);
writes benchmarks/results/reconstruction_tables.md. Split used: test (once, for these tables).
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
    if task == "hyperspectral" and honest.get("by_light"):
        lines += ["", "Hyperspectral, honest captures, by the scene's light (out-of-library: light the proposed "
                      "network's illuminant search does not hold):", "",
                  "| light | variant | PSNR (dB) | SSIM | SAM (rad) |", "| --- | --- | --- | --- | --- |"]
        for light, rows in honest["by_light"].items():
            for v, row in rows.items():
                lines.append(f"| {light} | {v.replace('_', '-')} | {row['psnr']:.4g} | {row['ssim']:.4g} | "
                             f"{row['sam']:.4g} |")
    return lines + [""]


def main(root: Path) -> None:
    lines = []
    for task in KEYS:
        honest = _load(root, task)
        if honest is not None:
            lines += task_table(task, honest, _load(root, f"{task}_clean"))
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "reconstruction_tables.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/ship9/eval"))
