"""Which simulation grid each error kind needs, measured on the design itself.

Errors whose simulation depends on the grid (``kinds.Kind.grid``: mask-level slivers, a turned relief) are
judged on a block of the design — ``block``² DOE pixels from the middle of its coded half, with its own
aperture — on grids refined s = 1, 2, 4 times and on a reference s = 8 times, each part carrying only that error
at the budget's value. The task metric is a sum of the coded PSF over the task's metric pixels divided by the
coded half's light (0.5), so twice the summed absolute PSF difference to the reference over those pixels bounds
the metric's error on the block. The block's aperture is smaller than the design's, so its PSF is broader and its
metric pixels catch less of its light and of the changes an error makes: each band's bound is multiplied by the
ratio of the light the metric pixels hold for the whole design to that for the block (error-free parts, at least
1; ``block_to_full``), which brings the block's bound to the whole design's scale (on the committed grating the
whole design's own 1×−2× difference lies within it: ``benchmarks/tolerance_grid.py``). The grid chosen for a
kind is the coarsest whose scaled bound is within ``tolerance``, and a Monte Carlo part is simulated on the
finest grid any of its errors needs — and no finer.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from doefab.tolerance.kinds import KINDS

__all__ = ["grid_study", "judge_grid", "GRIDS", "REFERENCE", "TOLERANCE", "block_design", "block_to_full"]

GRIDS = (1, 2, 4)
REFERENCE = 8
TOLERANCE = 0.005  # bound on the task metric's error from the grid


def block_design(design, block: int):
    """A ``block``² piece of ``design`` around the middle of its coded half (x < 0), as a design of its own
    (aperture = the block; three bands — first, middle, last — and the middle depth)."""
    from doefab.design.design import Design

    n = design.camera.doe_pixels
    b = int(min(block, n // 2))
    r0, c0 = (n - b) // 2, max(0, n // 4 - b // 2)
    levels = np.ascontiguousarray(design.levels[r0:r0 + b, c0:c0 + b])
    cam = design.camera.replace(doe_pixels=b, aperture_diameter=b * design.camera.doe_pitch)
    w = design.wavelengths
    pick = sorted({0, len(w) // 2, len(w) - 1})
    z = len(design.depths) // 2
    return Design(task=design.task, task_params=design.task_params, camera=cam,
                  wavelengths=tuple(w[i] for i in pick), depths=(design.depths[z],),
                  height=design.height[r0:r0 + b, c0:c0 + b], levels=levels, metrics=design.metrics,
                  extra={"bands": pick, "depth": z}, n_levels=design.n_levels)


def grid_study(judge, budget: dict, block: int = 128, tolerance: float = TOLERANCE, progress: bool = False,
               keep=None) -> dict:
    """{kind: {"value", "unit", "bound": {s: metric-error bound, scaled to the whole design}, "block_bound": {s:
    the block's own}, "seconds": {s: ...}, "grid": chosen s}} for the grid-dependent kinds present in ``budget``,
    "block_to_full": the scale per band, and "monte_carlo_grid": the finest of the chosen grids (``judge``: the
    design's ``PSFJudge``; its alignment chain is used on the block too, its error-free PSF gives the scale).
    ``keep(name, compute)``: what judges each kind (default: ``compute()``; ``partmemo.PartMemo.keep`` keeps each
    for a resumed study: its grids then come back keyed by text, "1", as a kept study's do)."""
    from doefab.tolerance.judge import PSFJudge
    from doefab.tolerance.study import compute_now

    kinds = [k for k in KINDS if k.grid and k.from_budget(budget) != 0.0]
    out: dict = {"block_px": block, "tolerance": tolerance, "reference_grid": REFERENCE, "kinds": {}}
    if not kinds:
        out["monte_carlo_grid"] = 1
        return out
    piece = block_design(judge.design, block)
    kernel = judge.task.kernel_size
    judges = {s: PSFJudge(piece, s, chain=judge.chain, margin=0.0) for s in (*GRIDS, REFERENCE)}
    # the metric sums the coded PSF over these pixels (fractions of the coded half's 0.5): twice the summed
    # absolute PSF error inside them bounds the metric's error
    masks = judge.task.band_masks(judge.fine)[[piece.extra["depth"]]][:, piece.extra["bands"]].double()
    scale = block_to_full(judge, piece, judges[1], masks)
    out["block_to_full"] = [round(float(v), 4) for v in scale.flatten()]

    def bound_of(diff, to_full=True):
        per_band = 2 * (diff.abs() * masks).sum(dim=(-1, -2))
        return float((per_band * scale if to_full else per_band).max())
    bar = None
    if progress:  # what runs, k of n error kinds, the time left
        from tqdm import tqdm

        bar = tqdm(total=len(kinds), desc="grid study", unit="error kind")

    def row(k) -> dict:
        part = k.budget_part(budget, judge.n_masks)
        psf = {}
        secs = {}
        for s, j in judges.items():
            t = time.perf_counter()
            with torch.no_grad():
                psf[s] = j.psfs(part, kernel=kernel)["coded"].double()
            secs[s] = round(time.perf_counter() - t, 3)
        ref = psf[REFERENCE]
        bound = {s: bound_of(psf[s] - ref) for s in GRIDS}
        chosen = next((s for s in GRIDS if bound[s] <= tolerance), REFERENCE)
        effect = bound_of(ref - judges[REFERENCE].nominal)
        return {"value": k.from_budget(budget) / k.si, "unit": k.unit, "bound": bound,
                "block_bound": {s: bound_of(psf[s] - ref, False) for s in GRIDS},
                "effect_bound": effect, "seconds": secs, "grid": chosen}

    keep = keep or compute_now
    for k in kinds:
        if bar is not None:
            bar.set_postfix(error=k.name)
        out["kinds"][k.name] = keep(k.name, lambda: row(k))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    out["monte_carlo_grid"] = max(v["grid"] for v in out["kinds"].values())
    return out


def block_to_full(judge, piece, block_judge, masks) -> torch.Tensor:
    """[depth, band] how many times more of the coded light the whole design's metric pixels hold than the
    block's (error-free parts; at least 1): the factor by which the block's PSF, broader for its smaller aperture,
    dilutes both its light and an error's change in those pixels."""
    whole = judge.nominal[[piece.extra["depth"]]][:, piece.extra["bands"]]
    light = (block_judge.nominal * masks).sum(dim=(-1, -2))
    return ((whole * masks).sum(dim=(-1, -2)) / light.clamp_min(1e-30)).clamp_min(1.0)


def judge_grid(study: dict, part, n_masks: int) -> int:
    """The grid a part (of a design of ``n_masks`` masks) needs: the finest any of its (nonzero) grid-dependent
    errors was given."""
    from doefab.tolerance.errors import PartErrors

    need = 1
    part, nominal = part.for_masks(n_masks), PartErrors().for_masks(n_masks)
    for k in KINDS:
        if k.grid and k.name in study.get("kinds", {}) and _has(part, k, nominal, n_masks):
            need = max(need, study["kinds"][k.name]["grid"])
    return need


def _has(part, k, nominal, n_masks: int) -> bool:
    """Whether ``part`` carries error kind ``k`` (it differs from the nominal part where ``k`` would)."""
    probe = k.build(k.sweep[-1] * k.si, n_masks).for_masks(n_masks)
    fields = [f for f in probe.__dataclass_fields__ if getattr(probe, f) != getattr(nominal, f)]
    return any(getattr(part, f) != getattr(nominal, f) for f in fields)

