"""Holder build times: mesh path (parameters → checked STL) and cadquery path (STEP + STL).

Writes benchmarks/results/holder_timing.md. Run: .venv/bin/python benchmarks/holder_timing.py
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

OUT = Path(__file__).parent / "results"


def main() -> None:
    from holder_cad.build import _export_mesh, _layout_for_print, assembly, build_parts
    from holder_cad.checks import run_checks
    from holder_cad.params import HolderParams

    OUT.mkdir(parents=True, exist_ok=True)
    p = HolderParams()

    def mesh_path(tmp: Path) -> None:
        parts = build_parts(p)
        checks = run_checks(parts, assembly(parts, p), p, expected_bodies=2)
        assert checks["passed"]
        _export_mesh(_layout_for_print(list(parts.values())), tmp / "holder.stl", "stl")

    with tempfile.TemporaryDirectory() as tmp:
        mesh_path(Path(tmp))  # warm-up: imports and first-use setup
        times = []
        for _ in range(5):
            t = time.perf_counter()
            mesh_path(Path(tmp))
            times.append(time.perf_counter() - t)
        from holder_cad.brep import build_brep, export_step

        cq_times = []
        for _ in range(2):
            t = time.perf_counter()
            solids = build_brep(p)
            export_step(solids, Path(tmp) / "holder.step")
            mesh_path(Path(tmp))
            cq_times.append(time.perf_counter() - t)
    text = ("| path | time (s) | what |\n| --- | --- | --- |\n"
            f"| mesh (manifold3d + trimesh) | {statistics.median(times):.2f} (median of 5) | parameters → both bodies "
            f"built, every check run, STL written |\n"
            f"| B-rep (cadquery) | {statistics.median(cq_times):.1f} (median of 2) | STEP of both bodies + the "
            f"checked STL |\n")
    (OUT / "holder_timing.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
