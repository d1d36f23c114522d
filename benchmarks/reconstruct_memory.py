"""Peak memory (and time) of ``doefab reconstruct``'s tiled reconstruction at camera sizes, per task.

Each (task, size) runs in a process of its own: the shipped network is loaded, a capture pair of that size is
made (a simulated 256² validation scene through the network's PSFs, repeated across the frame: the content a
camera gives, at no cost), what the writer keeps for the whole image is allocated and touched (the result; for
spectra its XYZ, the cube itself streaming to its ENVI file), and the first ``--rows`` rows of tiles are reconstructed
(``doefab.lab.reconstruct.iter_tiled``). Rows of tiles repeat the same work, so the peak of the first rows is the
peak of the reconstruction; the time of the whole run is extrapolated from the time per tile (labelled so).
``--rows 0`` runs every row and writes the files as ``doefab reconstruct`` does (``write_result_rows``, to a
temporary folder), so its peak includes the writers. The peak is the resident set size's high-water mark
(/proc/self/status VmHWM), reset once the captures are made; ``tracemalloc`` adds the peak of numpy's
allocations in the same span.

The peak is split into what the image itself needs — the two captures (3 × 4 bytes per pixel each), what the
writer keeps (4 bytes per kept channel per pixel) and the blend's band (one tile's height across the image,
channels + 1 float32) — and the rest: the network, the libraries and the tile's working set, which do not grow
with the image. Two or more sizes show that (the script fits peak − RSS after loading = a + b · megapixels).

Run (the published numbers: 24 megapixels, 6000 × 4000, and a quarter of it, every task, one row of tiles each;
about half an hour on 2 cores):
  .venv/bin/python benchmarks/reconstruct_memory.py --sizes 6000x4000 3000x2000
and the whole run of one task with its files written (an hour or more on 2 cores; writes reconstruct_memory.* too,
so run it with another --out):
  .venv/bin/python benchmarks/reconstruct_memory.py --tasks depth --sizes 6000x4000 --rows 0 --out /tmp/recmem_full
A quick check at toy size (writes elsewhere):
  .venv/bin/python benchmarks/reconstruct_memory.py --sizes 512x384 768x512 --tile 256 --out /tmp/recmem

``--accuracy SIZE SEEDS`` instead compares tiled with whole-image results on simulated validation scenes (the
published tolerance: ``--accuracy 1024 2 --tile 512``, about an hour on 2 cores; the whole-image HDR solve of a
1024² frame needs a few GB).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

OUT = Path(__file__).parent / "results"
TASKS = ("hdr", "hyperspectral", "depth")


def _status_mb(key: str = "VmRSS") -> float:
    """``key`` of /proc/self/status (Linux) in MiB: VmRSS, the resident set size now; VmHWM, its peak."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _reset_peak() -> None:
    """Start the peak resident set size (VmHWM) afresh from now (Linux ≥ 4.0): the network's PSFs and the
    simulated captures, made before, are not the reconstruction's."""
    Path("/proc/self/clear_refs").write_text("5")


def _scene(rec, size: int, seed: int = 0):
    """(scene, truth, coded, uncoded): a simulated ``size``² validation scene of ``rec``'s task and its captures
    through the network's own PSFs (truth: the radiance, spectra or depth the network should give)."""
    import numpy as np

    import doefab
    from doefab.reconstruction import data

    rng = np.random.default_rng(seed)
    dm = resp = None
    if rec.task == "hdr":
        scene = data.hdr_sample(rng, size, "val")
    elif rec.task == "hyperspectral":
        scene, resp = data.spectral_sample(rng, size, "val"), doefab.sensor_response(rec.pair.wavelengths)
    else:
        scene, dm = data.depth_sample(rng, size, "val")
    views = doefab.simulate_captures(scene, rec.pair, depth_map=dm, response=resp, seed=seed)
    return scene, (scene if dm is None else dm), *(np.asarray(v) for v in views)


def _pair(rec, width: int, height: int):
    """A capture pair of ``width`` × ``height`` px: one simulated 256² validation scene, repeated."""
    import numpy as np

    views = _scene(rec, 256)[2:]
    reps = (1, -(-height // 256), -(-width // 256))
    return [np.ascontiguousarray(np.tile(np.asarray(v), reps)[:, :height, :width]) for v in views]


def worker(task: str, width: int, height: int, tile: int, rows: int) -> dict:
    """One measurement (in this process): ``rows`` rows of tiles, or (0) the whole run as ``doefab reconstruct``
    makes it, files written (to a temporary folder)."""
    import tempfile
    import tracemalloc

    import numpy as np
    import torch

    import doefab
    from doefab.lab import reconstruct as R
    from doefab.lab.outputs import spectra_to_xyz, write_result_rows

    rec = doefab.load_reconstructor(task)
    base = _status_mb()
    coded, uncoded = _pair(rec, width, height)
    _reset_peak()
    overlap = R.default_overlap(rec)
    tile = max(tile, 2 * overlap)  # the smallest tile the default overlap allows
    ch, wl = R.output_channels(rec), rec.pair.wavelengths
    hp, wp = -(-height // 32) * 32, -(-width // 32) * 32
    th, tw = min(tile, hp), min(tile, wp)
    starts = (R.tile_starts(hp, th, overlap), R.tile_starts(wp, tw, overlap))
    kept = 3 if task == "hyperspectral" else ch  # what the writer holds: XYZ for spectra (the cube streams to disk)
    tracemalloc.start()
    t0 = time.perf_counter()
    blocks = R.iter_tiled(rec, coded, uncoded, tile, overlap)
    if rows <= 0:
        with tempfile.TemporaryDirectory() as tmp:
            write_result_rows(task, blocks, (ch, height, width), tmp, "bench", wl,
                              (min(rec.pair.depths), max(rec.pair.depths)))
        run_rows = len(starts[0])
    else:
        held = np.empty((kept, height, width), np.float32)
        held.fill(0.0)  # resident, as the whole run's is
        for i, (r, block) in enumerate(blocks):
            held[:, r:r + block.shape[1]] = spectra_to_xyz(block, wl) if task == "hyperspectral" else block
            if i + 1 >= rows:
                break
        run_rows = min(rows, len(starts[0]))
    seconds = time.perf_counter() - t0
    traced_peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    peak = _status_mb("VmHWM")
    arrays = (coded.nbytes + uncoded.nbytes + kept * 4 * height * width + (ch + 1) * 4 * th * wp) / 2**20
    tiles_run, total = run_rows * len(starts[1]), len(starts[0]) * len(starts[1])
    return {"task": task, "width_px": width, "height_px": height, "megapixels": width * height / 1e6,
            "tile_px": tile, "overlap_px": overlap, "tiles": total, "tiles_run": tiles_run,
            "files_written": rows <= 0, "rss_after_network_mb": round(base, 1), "peak_rss_mb": round(peak, 1),
            "image_arrays_mb": round(arrays, 1), "rest_mb": round(peak - base - arrays, 1),
            "numpy_traced_peak_mb": round(traced_peak, 1), "seconds_per_tile": round(seconds / tiles_run, 2),
            "extrapolated_total_s": round(seconds / tiles_run * total, 0), "torch_threads": torch.get_num_threads()}


def accuracy(task: str, size: int, tile: int, overlap: int | None, seeds: int) -> dict:
    """The tiled result against the whole-image result (mean and largest |difference| over the mean |result|;
    HDR in log(1 + radiance), split where the plain capture clips and where it does not) and both against the
    scene (the task's metrics), on ``seeds`` simulated ``size``² validation scenes."""
    import numpy as np

    import doefab
    from doefab.lab import reconstruct as R
    from doefab.reconstruction.metrics import metrics_for

    rec = doefab.load_reconstructor(task)
    rows = []
    for seed in range(seeds):
        _, truth, coded, uncoded = _scene(rec, size, seed)
        whole = rec(coded, uncoded)
        tiled = R.reconstruct_tiled(rec, coded, uncoded, tile, overlap)
        a, b = (np.log1p(whole), np.log1p(tiled)) if task == "hdr" else (whole, tiled)
        d = np.abs(a - b).reshape(-1, *a.shape[-2:]).max(axis=0)
        scale = float(np.abs(a).mean())
        row = {"seed": seed, "mean_rel_diff": float(d.mean()) / scale, "max_rel_diff": float(d.max()) / scale,
               "whole": metrics_for(task, whole, truth), "tiled": metrics_for(task, tiled, truth)}
        if task == "hdr":
            clipped = (uncoded >= 0.98).any(axis=0)
            row |= {"mean_rel_diff_unclipped": float(d[~clipped].mean()) / scale,
                    "mean_rel_diff_clipped": float(d[clipped].mean()) / scale if clipped.any() else None}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return {"task": task, "size_px": size, "tile_px": tile, "overlap_px": overlap or R.default_overlap(rec),
            "scenes": rows}


def _size(text: str) -> tuple[int, int]:
    w, h = (int(v) for v in text.lower().split("x"))
    return w, h


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", default=",".join(TASKS))
    ap.add_argument("--sizes", nargs="+", default=["6000x4000"], help="WIDTHxHEIGHT in pixels")
    ap.add_argument("--tile", type=int, default=512)
    ap.add_argument("--rows", type=int, default=1, help="rows of tiles to run (0: all, and write the files)")
    ap.add_argument("--out", default=str(OUT), help="folder of reconstruct_memory.json / .md")
    ap.add_argument("--accuracy", nargs=2, type=int, metavar=("SIZE", "SEEDS"),
                    help="instead: tiled against whole-image results on SEEDS simulated SIZE² scenes (--tile, "
                         "--overlap), written to reconstruct_accuracy.json")
    ap.add_argument("--overlap", type=int, default=None, help="with --accuracy (default: the PSF's kernel)")
    ap.add_argument("--worker", nargs=5, metavar=("TASK", "W", "H", "TILE", "ROWS"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.accuracy:
        res = [accuracy(t, a.accuracy[0], a.tile, a.overlap, a.accuracy[1]) for t in a.tasks.split(",")]
        Path(a.out).mkdir(parents=True, exist_ok=True)
        (Path(a.out) / "reconstruct_accuracy.json").write_text(json.dumps(res, indent=1))
        return
    if a.worker:
        t, w, h, tile, rows = a.worker
        print(json.dumps(worker(t, int(w), int(h), int(tile), int(rows))))
        return
    rows_out = []
    for task in a.tasks.split(","):
        for size in a.sizes:
            w, h = _size(size)
            cmd = [sys.executable, __file__, "--worker", task, str(w), str(h), str(a.tile), str(a.rows)]
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode:
                raise SystemExit(f"{task} at {size} failed:\n{res.stderr[-3000:]}")
            rows_out.append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(rows_out[-1], flush=True)
    _write(rows_out, Path(a.out), a)


def _fit(rows: list[dict]) -> dict:
    """The memory the reconstruction adds to the loaded network, peak − RSS after loading = a + b · megapixels,
    per task (least squares), where two or more sizes were measured."""
    import numpy as np

    fits = {}
    for task in dict.fromkeys(r["task"] for r in rows):
        pts = [(r["megapixels"], r["peak_rss_mb"] - r["rss_after_network_mb"]) for r in rows if r["task"] == task]
        if len({p for p, _ in pts}) >= 2:
            b, a = np.polyfit(*zip(*pts), 1)
            fits[task] = {"mb_fixed": round(float(a), 1), "mb_per_megapixel": round(float(b), 1)}
    return fits


def _write(rows: list[dict], out: Path, a) -> None:
    out.mkdir(parents=True, exist_ok=True)
    fits = _fit(rows)
    record = {"rows": rows, "fits": fits, "command": sys.argv}
    (out / "reconstruct_memory.json").write_text(json.dumps(record, indent=1))
    lines = ["Peak resident memory in MiB (2²⁰ bytes) from the captures in memory on (the peak is reset once they are "
             "made); without --rows 0 the files are not written.\n",
             "| task | size (px) | tile / overlap (px) | peak RSS (MiB) | image arrays (MiB) | rest (MiB) | "
             "s per tile | whole run (s) |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r['task']} | {r['width_px']} × {r['height_px']} | {r['tile_px']} / {r['overlap_px']} | "
                     f"{r['peak_rss_mb']:.0f} | {r['image_arrays_mb']:.0f} | {r['rest_mb']:.0f} | "
                     f"{r['seconds_per_tile']:.2f} | {r['extrapolated_total_s']:.0f} ({r['tiles']} tiles, "
                     f"{r['tiles_run']} run{', files written' if r['files_written'] else ': extrapolated'}) |")
    for task, f in fits.items():
        lines.append(f"\n{task}: the reconstruction adds ≈ {f['mb_fixed']:.0f} MiB + {f['mb_per_megapixel']:.1f} MiB "
                     f"per megapixel to the loaded network")
    text = "\n".join(lines) + "\n"
    (out / "reconstruct_memory.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
