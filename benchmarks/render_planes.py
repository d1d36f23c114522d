"""Where depth scenes are rendered: the previous rendering planes against this code's, in one run.

Honest depth captures are rendered through a fabricated part's PSFs at planes ``DEPTH_REFINE`` times finer than
the network's (``doefab.tolerance.conditions.fine_planes``), each pixel at the plane nearest its depth in inverse
depth, while the target keeps the scene's own depth. The previous rule spread 65 planes evenly in inverse depth
between the nearest and the farthest of the network's planes; for planes even in depth (the shipped design's:
1–5 m every 0.25 m) that is 16× finer than the network's spacing at 1 m but coarser than it beyond about 4.5 m,
where a depth could be rendered up to 0.15 m from its own. This code refines each interval of the network's
planes ``DEPTH_REFINE`` times (evenly in inverse depth within it), which keeps the network's planes among them.

Measures (1) the rendering error itself: for depths on a dense grid of the design's range, the distance in metres
to the plane each is rendered at, per depth bin; and (2) the shipped depth networks (proposed and both
ablations) on the synthetic validation split and the measured set (split ``real``) under honest captures made with
each rule (their own fabricated parts' PSFs at each rule's planes: the same parts, seeds and scenes), torch on one
thread. Split used: val and real (validation); the test and final splits are not read.

    .venv/bin/python benchmarks/render_planes.py --images 12 --size 256

Evaluations go to out/render_planes/<split>_<rule>/ (one already there for the same settings is reused); writes
benchmarks/results/render_planes.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from doefab.io import read_json  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SPLITS = ("val", "real")
BINS = ((1.0, 1.5), (1.5, 2.0), (2.0, 2.5), (2.5, 3.0), (3.0, 4.0), (4.0, 5.0))
METRICS = (("mae", "MAE (m)"), ("rmse", "RMSE (m)"), ("delta125", "δ<1.25"))


def previous_planes(depths, refine: int | None = None) -> tuple:
    """The rule this code replaces: ``(n − 1)·refine + 1`` planes evenly in inverse depth from the nearest of
    ``depths`` to the farthest."""
    from doefab.tolerance.conditions import DEPTH_REFINE

    refine = refine or DEPTH_REFINE
    inv = np.linspace(1 / min(depths), 1 / max(depths), (len(depths) - 1) * refine + 1)
    return tuple(float(1 / v) for v in inv)


def rules() -> dict:
    from doefab.tolerance.conditions import fine_planes

    return {"previous": previous_planes, "this code": fine_planes}


def rendering_error(planes, near: float, far: float, n: int = 400_001) -> dict:
    """{bin: (mean, max) metres} between a depth and the plane it is rendered at (nearest in inverse depth), for
    depths evenly spaced in metres over [near, far]."""
    z = np.linspace(near, far, n)
    inv = np.sort(1 / np.asarray(planes, np.float64))
    j = np.clip(np.searchsorted(inv, 1 / z), 1, len(inv) - 1)
    lo, hi = inv[j - 1], inv[j]
    at = np.where(1 / z - lo < hi - 1 / z, lo, hi)
    err = np.abs(1 / at - z)
    out = {}
    for a, b in BINS:
        m = (z >= a) & ((z < b) | (b == far) & (z <= b))
        if m.any():
            out[f"{a:g}–{b:g}"] = (float(err[m].mean()), float(err[m].max()))
    out["all"] = (float(err.mean()), float(err.max()))
    return out


def run_rule(rule: str, split: str, images: int, size: int, work: Path) -> dict:
    """The shipped depth networks on ``split`` under honest captures rendered at ``rule``'s planes."""
    import doefab.tolerance.conditions as C
    from doefab.reconstruction.evaluate import evaluate, one_thread

    out = work / f"{split}_{rule.replace(' ', '_')}"
    f = out / "metrics.json"
    if f.is_file():
        done = read_json(f)
        if (done["images"], done["size_px"]) == (images, size):
            print(f"{split} {rule}: reusing {f}")
            return done
    keep = C.fine_planes
    C.fine_planes = rules()[rule]  # the parts' PSFs (and their cache key) at this rule's planes
    try:
        with one_thread():
            cond = C.for_splits("depth", None, "honest", (split,), progress=True)[split]
        return evaluate("depth", out, images=images, size=size, conditions=cond, split=split)
    finally:
        C.fine_planes = keep


def markdown(res: dict, code: str, cmd: str) -> str:
    rows = [f"Produced by `{cmd}` at {code}.", "",
            "Distance between a depth and the plane it is rendered at (metres; depths evenly spaced over the "
            f"shipped depth design's {res['near']:g}–{res['far']:g} m, {res['network_planes']} network planes; "
            "mean / largest):", "",
            "| depth (m) | network's own planes | previous rendering planes | this code's rendering planes |",
            "| --- | --- | --- | --- |"]
    err = res["rendering_error"]
    for b in err["this code"]:
        rows.append(f"| {b} | " + " | ".join(f"{err[r][b][0]:.3f} / {err[r][b][1]:.3f}"
                                             for r in ("network", "previous", "this code")) + " |")
    rows += ["", f"Rendering planes: previous {res['planes']['previous']} ({res['on_network_planes']['previous']} "
             f"of them on a network plane), this code {res['planes']['this code']} "
             f"({res['on_network_planes']['this code']} on a network plane: the network's planes are among them).",
             ""]
    for split in SPLITS:
        e = res["evaluations"][split]
        head = ["variant"] + [f"{name} {r}" for _, name in METRICS for r in ("previous", "this code")]
        rows += [f"**{split}**: {e['previous']['images']} scenes of {e['previous']['size_px']}² px, honest captures "
                 f"({e['previous']['conditions'].get('parts', 0)} fabricated parts), the shipped networks; torch on "
                 f"{e['previous']['threads']} thread", "", "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
        for v in e["this code"]["rows"]:
            cells = [f"{e[r]['rows'][v][k]:.4g}" for k, _ in METRICS for r in ("previous", "this code")]
            rows.append(f"| {v.replace('_', '-')} | " + " | ".join(cells) + " |")
        rows.append("")
    return "\n".join(["# Where depth scenes are rendered", ""] + rows)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--images", type=int, default=12)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "render_planes")
    a = ap.parse_args(argv)
    from doefab.design.design import Design

    net = Design.load(ROOT / "masks" / "half-ring" / "design").depths
    near, far = min(net), max(net)
    planes = {r: f(net) for r, f in rules().items()}
    res = {"network_planes": len(net), "near": near, "far": far,
           "planes": {r: len(p) for r, p in planes.items()},
           "on_network_planes": {r: int(sum(np.isclose(p, z, rtol=1e-12, atol=0).any() for z in net))
                                 for r, p in planes.items()},
           "rendering_error": {"network": rendering_error(net, near, far),
                               **{r: rendering_error(p, near, far) for r, p in planes.items()}},
           "evaluations": {s: {r: run_rule(r, s, a.images, a.size, a.work) for r in planes} for s in SPLITS}}
    code = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip()
    cmd = f".venv/bin/python benchmarks/render_planes.py --images {a.images} --size {a.size}"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "render_planes.json").write_text(json.dumps(res, indent=1, default=str) + "\n")
    (RESULTS / "render_planes.md").write_text(markdown(res, code, cmd) + "\n")
    print(markdown(res, code, cmd))


if __name__ == "__main__":
    main()
