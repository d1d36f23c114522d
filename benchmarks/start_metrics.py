"""Task metrics of each task's starting height map (continuous and 16-level), on the full preset grid.

Run: .venv/bin/python benchmarks/start_metrics.py  (writes benchmarks/results/start_metrics.md)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

import doefab
from doefab.tasks import get_task

OUT = Path(__file__).parent / "results"


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    lines = ["| task | continuous mean / worst | 16-level mean / worst |", "| --- | --- | --- |"]
    for name in ("streak", "grating", "half-ring"):
        task = get_task(name)
        cam = doefab.Camera.preset(task.preset)
        task.bind(cam)
        plan = doefab.PSFPlan(cam, task.wavelengths(cam), task.depths(cam), task.kernel_size, halves=("coded",))
        h = task.init_height(cam, np.random.default_rng(0))
        with torch.no_grad():
            c = task.metric(plan(h).coded, cam)
            q = task.metric(plan(doefab.quantize_height(h, cam)).coded, cam)
        lines.append(f"| {name} | {c['value']:.3f} / {c['worst']:.3f} | {q['value']:.3f} / {q['worst']:.3f} |")
        print(lines[-1], flush=True)
    (OUT / "start_metrics.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
