"""Where the shipped depth network's errors lie: δ<1.25 and MAE of the proposed network by the scene's local
texture and by distance to a depth edge, on the validation and on the test scenes of Table 3 (the same 12
scenes of 256² px and the same honest captures as `doefab evaluate --task depth`).

    .venv/bin/python benchmarks/depth_error_sources.py [--images 12]

Depth from defocus reads depth from how the two halves blur the scene's detail: where the scene is flat there
is little to read (the cross-blur cost is nearly flat) and the network carries depth in from the surroundings.
Two measures of the true radiance's luminance, each relative to its local mean in a 15-pixel window: its
contrast (standard deviation) and its fine detail (RMS of the luminance minus its 2-pixel Gaussian blur). A
depth edge is a jump of more than 2 % between neighbouring pixels of the true depth. A last table gives the
fine detail of 48 scenes per split (train, val, test) generated as the evaluation generates them, from their
content alone. A counterfactual row reweights one split's per-bin δ by the other's shares of pixels: how much
of the gap between the splits their mix of detail accounts for. A last table bins the errors by the true depth,
beside the measured depth set's (split ``real``, ``doefab evaluate --split real``: nine Middlebury 2014 scenes,
``realdata.depth_scenes``, under the same honest captures): each split restricted to the measured set's depths,
and reweighted to its shares of pixels per depth bin, compares like with like. This analysis chooses nothing.
Writes benchmarks/results/depth_error_sources.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from doefab.io import atomic_write_text  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
TEXTURE_BINS = (0.0, 0.01, 0.03, 0.1, np.inf)  # local relative contrast
EDGE_BINS = (0.0, 3.0, 10.0, np.inf)  # pixels from a depth edge
DEPTH_BINS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, np.inf)  # metres (the committed design's planes: 1–5 m)
WINDOW_PX = 15
EDGE_JUMP = 0.02
DETAIL_PX = 2.0


def local_contrast(scene: np.ndarray, window: int = WINDOW_PX, detail_px: float | None = None) -> np.ndarray:
    """[H, W] standard deviation over mean of the luminance of ``scene`` [3, H, W] in a ``window`` square; with
    ``detail_px``, of its fine detail only (the luminance minus its Gaussian blur of that σ)."""
    from scipy.ndimage import gaussian_filter, uniform_filter

    lum = scene.mean(axis=0).astype(np.float64)
    m = uniform_filter(lum, window, mode="reflect")
    if detail_px:
        hp = lum - gaussian_filter(lum, detail_px, mode="reflect")
        return np.sqrt(np.maximum(uniform_filter(hp**2, window, mode="reflect"), 0.0)) / np.maximum(m, 1e-6)
    var = np.maximum(uniform_filter(lum**2, window, mode="reflect") - m**2, 0.0)
    return np.sqrt(var) / np.maximum(m, 1e-6)


def edge_distance(depth: np.ndarray, jump: float = EDGE_JUMP) -> np.ndarray:
    """[H, W] distance (pixels) to the nearest pixel pair whose depths differ by more than ``jump`` (relative)."""
    from scipy.ndimage import distance_transform_edt

    ld = np.log(depth.astype(np.float64))
    edge = np.zeros(depth.shape, bool)
    dy, dx = np.abs(np.diff(ld, axis=0)) > np.log1p(jump), np.abs(np.diff(ld, axis=1)) > np.log1p(jump)
    edge[:-1] |= dy
    edge[1:] |= dy
    edge[:, :-1] |= dx
    edge[:, 1:] |= dx
    return distance_transform_edt(~edge) if edge.any() else np.full(depth.shape, np.inf)


def eval_scene(split: str, index: int, size: int, margin: int, depths) -> tuple:
    """(scene [3, S, S], depth [S, S]) of sample ``index`` as the evaluation makes it: generated with a margin of
    ``margin`` pixels between the nearest and farthest of ``depths``, cropped back to ``size``."""
    from doefab.reconstruction.data import depth_sample, sample_rng

    finite = [z for z in depths if np.isfinite(z)]
    scene, depth = depth_sample(sample_rng(split, index), size + 2 * margin, split, near=min(finite), far=max(finite))
    return scene[:, margin:margin + size, margin:margin + size], depth[margin:margin + size, margin:margin + size]


def split_pixels(split: str, images: int, size: int = 256) -> dict:
    """Per pixel of the split's scenes: texture, edge distance, |error| (m) and whether δ<1.25 holds."""
    import torch

    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.metrics import depth_pixels
    from doefab.reconstruction.specs import crop_margin, make_batch, psf_pair
    from doefab.tolerance.conditions import for_splits

    pair, _ = psf_pair("depth")
    cond = for_splits("depth", None, "honest", (split,))[split]
    rec = load_reconstructor("depth", "proposed")
    m = crop_margin("depth", pair)
    cols = {"texture": [], "detail": [], "edge": [], "abs_err": [], "ok": [], "depth": []}
    for i in range(images):
        coded, uncoded, target = make_batch("depth", split, [i], size, pair, conditions=cond, images=images)
        scene, depth = eval_scene(split, i, size, m, cond.pair_for(i, pair).depths)
        if not np.array_equal(depth, target[0].numpy()):
            raise SystemExit(f"scene {i} of {split}: regenerated depth differs from the evaluation's")
        with torch.no_grad():
            _p, err, within = depth_pixels(np.asarray(rec(coded[0], uncoded[0])), depth)
        cols["texture"].append(local_contrast(scene).ravel())
        cols["detail"].append(local_contrast(scene, detail_px=DETAIL_PX).ravel())
        cols["edge"].append(edge_distance(depth).ravel())
        cols["abs_err"].append(err.ravel())
        cols["ok"].append(within.ravel())
        cols["depth"].append(depth.ravel())
    return {k: np.concatenate(v) for k, v in cols.items()}


def real_pixels(images: int, size: int = 256) -> dict:
    """Per measured pixel of the measured depth set's crops (split ``real``, made and captured as ``doefab evaluate
    --split real`` makes them): true depth, |error| (m) and whether δ<1.25 holds."""
    import torch

    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.metrics import depth_pixels
    from doefab.reconstruction.specs import make_batch, psf_pair
    from doefab.tolerance.conditions import for_splits

    pair, _ = psf_pair("depth")
    cond = for_splits("depth", None, "honest", ("real",))["real"]
    rec = load_reconstructor("depth", "proposed")
    cols = {"abs_err": [], "ok": [], "depth": []}
    for i in range(images):
        coded, uncoded, target = make_batch("depth", "real", [i], size, pair, conditions=cond, images=images)
        t = target[0].numpy()
        known = np.isfinite(t)
        with torch.no_grad():
            pred = np.asarray(rec(coded[0], uncoded[0]))
        _p, err, within = depth_pixels(pred[known], t[known])
        cols["abs_err"].append(err)
        cols["ok"].append(within)
        cols["depth"].append(t[known])
    return {k: np.concatenate(v) for k, v in cols.items()}


def depth_lines(data: dict) -> list[str]:
    """The errors by true depth for every split in ``data``, each split restricted to the measured set's depths
    and reweighted to its shares of pixels per bin."""
    per = {s: binned(px, "depth", DEPTH_BINS) for s, px in data.items()}
    lines = ["| true depth (m) | " + " | ".join(f"{s}: share of pixels | {s}: δ<1.25 | {s}: MAE (m)" for s in data)
             + " |", "| --- |" + " --- | --- | --- |" * len(data)]
    for j, (label, *_r) in enumerate(per[next(iter(data))]):
        lines.append(f"| {label} | " + " | ".join(bin_cells(per[s][j]) for s in data) + " |")
    real = data.get("real")
    if real is None:
        return lines + [""]
    lo, hi = float(real["depth"].min()), float(real["depth"].max())
    inside = {s: (px["depth"] >= lo) & (px["depth"] <= hi) for s, px in data.items()}
    lines += ["", f"Restricted to the measured set's depths ({lo:.2f}–{hi:.2f} m): " + "; ".join(
        f"{s} δ<1.25 {px['ok'][inside[s]].mean():.3f}, MAE {px['abs_err'][inside[s]].mean():.3f} m "
        f"({100 * inside[s].mean():.0f} % of its pixels)" for s, px in data.items()) + ". Reweighted to the measured "
        "set's shares of pixels per depth bin: " + "; ".join(
        f"{s} δ<1.25 {reweighted(per[s], per['real']):.3f}" for s in data if s != "real") + ".", ""]
    return lines


def detail_shares(split: str, images: int, size: int = 256) -> np.ndarray:
    """Share of the pixels of ``split``'s first ``images`` depth scenes (made as the evaluation makes them) in
    each fine-detail bin: content only, no network."""
    from doefab.reconstruction.specs import crop_margin, psf_pair

    pair, _ = psf_pair("depth")
    m = crop_margin("depth", pair)
    d = np.concatenate([local_contrast(eval_scene(split, i, size, m, pair.depths)[0], detail_px=DETAIL_PX).ravel()
                        for i in range(images)])
    return np.histogram(d, bins=np.array(TEXTURE_BINS))[0] / d.size


def bin_cells(row: tuple) -> str:
    """A ``binned`` row's share, δ<1.25 and MAE cells; "—" for a bin that holds no pixel."""
    _label, share, ok, mae = row
    return f"{share:.3f} | " + ("— | —" if np.isnan(ok) else f"{ok:.3f} | {mae:.3f}")


def bin_label(lo: float, hi: float) -> str:
    return f"≥ {lo:g}" if np.isinf(hi) else f"{lo:g}–{hi:g}"


def binned(px: dict, key: str, edges) -> list:
    """(label, share of pixels, δ<1.25, MAE) per bin of ``px[key]``."""
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (px[key] >= lo) & ((px[key] < hi) | np.isinf(hi))  # "≥ lo" holds inf (a scene with no edge)
        rows.append((bin_label(lo, hi), sel.mean(), px["ok"][sel].mean() if sel.any() else np.nan,
                     px["abs_err"][sel].mean() if sel.any() else np.nan))
    return rows


def reweighted(rows: list, like: list) -> float:
    """δ<1.25 of ``rows`` (``binned``) had its pixels fallen into the bins in the shares of ``like``."""
    pairs = [(w, d) for (_l, _s, d, _m), (_l2, w, _d2, _m2) in zip(rows, like) if w > 0 and not np.isnan(d)]
    return float(sum(w * d for w, d in pairs) / sum(w for w, _ in pairs))


def table(data: dict, images: int) -> str:
    lines = [f"The shipped proposed depth network on {images} scenes of 256² px per split, honest captures "
             "(`.venv/bin/python benchmarks/depth_error_sources.py`).", ""]
    by_depth = depth_lines(data)
    data = {s: px for s, px in data.items() if s != "real"}  # texture and edges: of generated scenes only
    per_key = {}
    for key, edges, head in (("texture", TEXTURE_BINS, f"local relative contrast ({WINDOW_PX}-px window)"),
                             ("detail", TEXTURE_BINS, f"fine detail: relative contrast above a {DETAIL_PX:g}-px blur"),
                             ("edge", EDGE_BINS, "distance to a depth edge (px)")):
        lines += [f"| {head} | " + " | ".join(f"{s}: share of pixels | {s}: δ<1.25 | {s}: MAE (m)" for s in data)
                  + " |", "| --- |" + " --- | --- | --- |" * len(data)]
        per = per_key[key] = {s: binned(px, key, edges) for s, px in data.items()}
        for j, (label, *_r) in enumerate(next(iter(per.values()))):
            lines.append(f"| {label} | " + " | ".join(bin_cells(per[s][j]) for s in data) + " |")
        lines.append("")
    if set(data) == {"val", "test"}:
        det = per_key["detail"]
        lines += ["Reweighted by fine detail: " + "; ".join(
            f"{a}'s δ<1.25 per bin with {b}'s shares of pixels {reweighted(det[a], det[b]):.3f}"
            for a, b in (("test", "val"), ("val", "test"))) + ".", ""]
    shares = {s: detail_shares(s, 48) for s in ("train", "val", "test")}
    lines += [f"Scene content alone, 48 scenes of 256² px per split made as the evaluation makes them: share of "
              f"pixels by fine detail (above a {DETAIL_PX:g}-px blur).", "", "| fine detail | " + " | ".join(shares) + " |",
              "| --- |" + " --- |" * len(shares)]
    for j, (lo, hi) in enumerate(zip(TEXTURE_BINS[:-1], TEXTURE_BINS[1:])):
        lines.append(f"| {bin_label(lo, hi)} | " + " | ".join(f"{v[j]:.3f}" for v in shares.values()) + " |")
    lines.append("")
    lines.append("All pixels: " + "; ".join(f"{s} δ<1.25 {px['ok'].mean():.3f}, MAE {px['abs_err'].mean():.3f} m"
                                            for s, px in data.items()) + ".")
    lines += ["", "By the true depth, beside the measured depth set's measured pixels (split real: the measured "
              "scenes' depths, `realdata.depth_scenes`).", ""] + by_depth
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=12)
    args = ap.parse_args()
    data = {s: split_pixels(s, args.images) for s in ("val", "test")}
    data["real"] = real_pixels(args.images)
    text = table(data, args.images)
    atomic_write_text(OUT / "depth_error_sources.md", text + "\n")
    print(text)


if __name__ == "__main__":
    main()
