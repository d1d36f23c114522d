"""The seed's Tables 1–3 on our held-out test split, from `doefab evaluate` outputs, as Markdown.
Run: .venv/bin/python benchmarks/reconstruction_tables.py out/eval (expects out/eval/<task>/metrics.json);
writes benchmarks/results/reconstruction_tables.md."""

from __future__ import annotations

import json
import sys
from pathlib import Path

OUT = Path(__file__).parent / "results"
KEYS = {"hdr": ("rmse", "psnr", "rmse_highlight", "psnr_highlight"), "hyperspectral": ("psnr", "ssim", "sam"),
        "depth": ("mae", "rmse", "log10", "delta125")}
UNITS = {"rmse": "", "psnr": " (dB)", "rmse_highlight": "", "psnr_highlight": " (dB)", "ssim": "", "sam": " (rad)",
         "mae": " (m)", "log10": "", "delta125": ""}


def main(root: Path):
    lines = []
    for task, keys in KEYS.items():
        f = root / task / "metrics.json"
        if not f.is_file():
            continue
        m = json.loads(f.read_text())
        lines += [f"**{task}** — {m['test_images']} held-out test scenes of {m['size_px']}² px (seed {m['seed']}):", "",
                  "| variant | " + " | ".join(k + UNITS[k] for k in keys) + " | training: steps, minutes, lr schedule |",
                  "| --- |" + " --- |" * (len(keys) + 1)]
        for v, row in m["rows"].items():
            lines.append(f"| {v.replace('_', '-')} | " + " | ".join(f"{row[k]:.4g}" for k in keys) +
                         f" | {_training(m['weights'][v])} |")
        lines.append("")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "reconstruction_tables.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _training(w: dict) -> str:
    # weights evaluated before the schedule existed were trained at a constant learning rate
    return f"{w['steps']}, {w['wall_time_s'] / 60:.0f} min, {w.get('lr_schedule', 'constant')}"


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/eval"))
