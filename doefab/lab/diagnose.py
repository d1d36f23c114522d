"""Diagnose a fabricated part: the tolerance study's part model (``lab.partmodel``) fitted to its measured PSF pair.

**Misfit.** The sum over pixels, halves, bands and planes of the squared difference between the model's PSFs and
the measured ones (both scaled per half, plane and band to the error-free part's light in the kernel).

**Fit.** Levenberg–Marquardt (``scipy.optimize.least_squares``, trust-region reflective, bounded at ±``BOUND``
budget σ) on the residual vector, its Jacobian by forward differences: the relief's exact-area histogram is
piecewise linear in the overlays and the judge has no gradient through it, but the misfit is a sum of squares,
which a Gauss–Newton method solves in far fewer parts than a derivative-free one (nlopt's BOBYQA took 600 parts
on a 160-pixel grating to stop at 4.6 times the true part's misfit, where this reached it in about 500).

1. From the error-free part (its overlays nudged off the kink at zero) and ``starts − 1`` parts drawn from the
   budget (``tolerance.errors.sample_errors``); a PSF responds to an overlay's size more than to its sign, with
   a kink where a mask crosses another, so the misfit has many local minima.
2. The pixels weighed by a noise model fitted to the best start's residuals (``PartModel.reweight``: shot noise
   makes the PSF's core far noisier than its tails), the errors the fit holds modelled around it
   (``PartModel.hold``: the mean PSF change of ``HOLD_DRAWS`` parts drawn with the masks' rotations, the roughness
   and each held error joins the model's PSFs, their spread whitens the residual: generalised least squares, so
   that a rough surface's scatter does not pull the fitted errors) and the fit resumed, ``REWEIGHT`` times; the
   other starts' ends whose misfit came within ``RIVAL`` of the best (and lie apart from it and each other) are
   resumed weighted too; each is polished by ``POLISH`` Gauss–Newton steps on the finer grid of step 4 and the
   best there kept (the design grid's flat cells misplace the slivers an overlay cuts, differently in each fit).
3. Each overlay, and every overlay along one axis at once, tried mirrored (``mirror``), and each overlay scanned
   for other basins (``scan``: the local minima of its misfit profile with the other errors held); each such
   point whose misfit after one Gauss–Newton step rose by less than ``SCREEN`` s² is resumed to its own optimum
   and polished as in step 2, the best of every fit found taken and the test repeated (twice at most). An
   overlay's sign test takes its resumed mirror where that kept the other sign (one step from a mirror overstates
   its rise).
4. Gauss–Newton steps on a grid ``partmodel.FINE``× finer (``refine``), with the design grid's Jacobian.

**Uncertainty** and **identifiable**: ``lab.uncertainty`` (the curvature's σ with the held errors' share, widened to
other fits the recordings do not tell apart).
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch

from doefab.lab.partmodel import BOUND, HELD_DRAWS, HOLD_DRAWS, STEP, PartModel, held_changes, held_errors, scaled
from doefab.lab.uncertainty import (MAX_CORRELATION, MAX_SIGMA, MIRROR_CHI2, curvature, estimate, jacobian, refine,
                                    tolerance)
from doefab.tolerance.errors import PartErrors

__all__ = ["diagnose", "fitted_pair", "part_errors", "fit", "jacobian", "curvature", "estimate", "held_errors",
           "tolerance", "held_changes", "MAX_CORRELATION", "MAX_SIGMA", "MIRROR_CHI2", "REWEIGHT", "HELD_DRAWS",
           "HOLD_DRAWS", "STARTS"]

REWEIGHT = 2  # noise-model fits, each followed by a resumed fit
MAX_STEPS = 40  # Levenberg–Marquardt iterations per fit
RIVAL = 1.0  # starts whose unweighted misfit is within this fraction of the best's are fitted weighted too
NUDGE = 0.25  # budget σ: the error-free start's overlays, off the kink at zero
SCREEN = 200.0  # a mirror or scanned basin whose one-step misfit rise (s²) is below this is resumed to its optimum
SAME = 0.1  # budget σ: two fits closer than this in every error are the same fit
POLISH = 3  # Gauss–Newton steps on the finer grid before fits are compared
SCAN = np.linspace(-3.5, 3.5, 15)  # budget σ: each overlay's values tried with the others held (``scan``)
STARTS = 8  # fits from the error-free part and parts drawn from the budget (benchmarks/diagnose_coverage.py)


def _starts(model: PartModel, starts: int, seed: int) -> list[np.ndarray]:
    """The error-free part, its overlays nudged by ±``NUDGE`` σ (signs drawn with ``seed``), and ``starts − 1``
    parts drawn from the budget, in budget σ (inside the bounds). A PSF responds to an overlay's size almost alike
    either way, with a kink at zero: a fit started there sees no slope along it."""
    from doefab.tolerance.errors import sample_errors

    rng = np.random.default_rng(seed)
    first = np.array([NUDGE * rng.choice((-1.0, 1.0)) if p.key == "overlay" else 0.0 for p in model.free])
    out = [first]
    for i in range(starts - 1):
        drawn = sample_errors(model.budget, rng, seed=i, n_masks=model.n_masks)
        out.append(np.clip(scaled(model.params, drawn, model.n_masks), -0.9 * BOUND, 0.9 * BOUND))
    return out


def _solve(model: PartModel, x0: np.ndarray) -> tuple[np.ndarray, float]:
    """(optimum, misfit) of one bounded Levenberg–Marquardt fit from ``x0`` with the model's current weights."""
    from scipy.optimize import least_squares

    got = least_squares(model.residual, x0, jac="2-point", bounds=(-BOUND, BOUND), method="trf", x_scale=1.0,
                        diff_step=STEP, ftol=1e-6, xtol=1e-4, gtol=1e-10, max_nfev=MAX_STEPS)
    return got.x, 2.0 * float(got.cost)


def fit(model: PartModel, starts: int = STARTS, seed: int = 0) -> dict:
    """{"x": the optimum (budget σ), "r", "jac": the weighted residual (on the finer grid) and the Jacobian there,
    "mirror": each fitted overlay's mirror test (``mirror``: rise of the misfit in s², and the residual's change),
    "others": [(point, rise of the weighted misfit, change of the weighted residual)] of the other fits found
    (rival starts, resumed mirrors and resumed scanned basins on the finer grid, one-step mirrors on the design
    grid), "grid": each error's grid uncertainty (budget σ), "starts": [{"misfit", "parts"}] per start
    (unweighted), "noise": [{"a", "b"}] per half, plane and band (the pixels' variance a·PSF + b)}: see the module
    docstring."""
    runs, ends = [], []
    for x0 in _starts(model, starts, seed):
        before = model.evaluations
        x, f = _solve(model, x0)
        runs.append({"misfit": f, "parts": model.evaluations - before})
        ends.append((f, x))
    ends.sort(key=lambda e: e[0])
    x, noise = ends[0][1], None
    for _ in range(REWEIGHT):
        noise = model.reweight(x)
        model.hold(held_changes(model, x, HOLD_DRAWS, seed, stream=41))
        x, f = _solve(model, x)
    rivals = _distinct([e[1] for e in ends[1:] if e[0] <= ends[0][0] * (1 + RIVAL)], x)
    found = sorted([_polish(model, xc) for xc in [x] + [_solve(model, xr)[0] for xr in rivals]], key=lambda e: e[0])
    x = found[0][1]
    r, jac = jacobian(model, x)
    for turn in range(3):  # the mirrors resumed; a better one is taken and the test repeated, twice at most
        dchi, tried = mirror(model, x, r, jac)
        mirrors = [(xm, float(rm @ rm) - float(r @ r), rm - r) for xm, rm, _ in tried]
        s2 = float(r @ r) / max(r.size - len(x), 1)
        resumed = [(flip, _polish(model, _solve(model, xm)[0])) for (xm, rise, _), (_, _, flip) in zip(mirrors, tried)
                   if rise / s2 <= SCREEN]
        resumed += [((), _polish(model, _solve(model, xm)[0])) for xm, rm in scan(model, x, jac)
                    if (float(rm @ rm) - float(r @ r)) / s2 <= SCREEN]
        found = sorted(found + [e for _, e in resumed], key=lambda e: e[0])
        if np.max(np.abs(found[0][1] - x), initial=0.0) <= SAME or turn == 2:  # the same fit: done
            break
        x = found[0][1]
        r, jac = jacobian(model, x)
    if not np.array_equal(found[0][1], x):  # the best fit found: within ``SAME`` of the last, or the third turn's
        x = found[0][1]
        r, jac = jacobian(model, x)
    best = found[0]
    for flip, e in resumed:  # an overlay's sign: its resumed mirror, where it kept the other sign, against the best
        i = flip[0] if len(flip) == 1 else None
        if i is not None and e[2][i] * best[2][i] < 0 and (e[0] - best[0]) / s2 < dchi["rise"][i]:
            dchi["rise"][i], dchi["change"][i] = (e[0] - best[0]) / s2, e[3] - best[3]
    fine, r_fine = refine(model, x, jac)
    # the rivals against the best's own polished entry (as many finer-grid steps as theirs)
    others = [(xo, fo - best[0], ro - best[3]) for fo, xd, xo, ro in found if not np.array_equal(xd, x)] + mirrors
    return {"x": fine, "r": r_fine, "jac": jac, "mirror": dchi, "others": others, "grid": np.abs(fine - x) / 3,
            "starts": runs, "noise": noise}


def _distinct(points: list, first: np.ndarray) -> list:
    """The ``points`` that lie more than ``SAME`` budget σ (in every error at once) from ``first`` and each other."""
    out, seen = [], [first]
    for xp in points:
        if all(np.max(np.abs(xp - q), initial=0.0) > SAME for q in seen):
            out.append(xp)
            seen.append(xp)
    return out


def _polish(model: PartModel, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(weighted misfit on the finer grid, the design-grid point ``x``, the point and its weighted residual on the
    finer grid) after ``POLISH`` Gauss–Newton steps there: fits are compared on the finer grid, closer to the part
    than the design grid's flat cells."""
    _, jac = jacobian(model, x)
    xf, rf = refine(model, x, jac, steps=POLISH)
    return float(rf @ rf), x, xf, rf


def mirror(model: PartModel, x: np.ndarray, r: np.ndarray, jac: np.ndarray) -> tuple[dict, list]:
    """The overlays' signs tested: a PSF responds to how far a mask moved against the others and against the
    chrome almost alike either way, so the part with one overlay negated, and the part with every overlay along
    one axis negated, may fit as well. Each is tried with the other errors moved by one Gauss–Newton step
    (``jac``: the Jacobian at ``x``). Returns ({"rise": per fitted error the weighted misfit's rise from ``x`` to
    its own mirror, in units of s², inf for errors not tested, "change": per fitted error its mirror's weighted
    residual less ``r``, None where not tested}; [(mirrored point, its weighted residual, the overlays negated)]
    of every one tried)."""
    n, p = jac.shape
    s2 = float(r @ r) / max(n - p, 1)
    free = model.free
    singles = [[i] for i, prm in enumerate(free) if prm.key == "overlay"]
    axes = [[i for i, prm in enumerate(free) if prm.key == "overlay" and prm.axis == a] for a in "xy"]
    dchi, change, tried = np.full(p, np.inf), [None] * p, []
    for flip in singles + [a for a in axes if len(a) > 1]:
        xm = x.copy()
        xm[flip] = -x[flip]
        rm = _step_others(model, xm, model.residual(xm), jac, flip)
        tried.append((xm, rm, flip))
        if len(flip) == 1:
            dchi[flip[0]] = (float(rm @ rm) - float(r @ r)) / s2
            change[flip[0]] = rm - r
    return {"rise": dchi, "change": change}, tried


def scan(model: PartModel, x: np.ndarray, jac: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Other basins along each overlay: the misfit at its values ``SCAN`` with the other errors held, and each
    local minimum of that profile more than a step from ``x`` moved by one Gauss–Newton step of the others
    (``jac``: the Jacobian at ``x``). Returns [(point, its weighted residual)]. A mask's overlay against the
    others has a minimum wherever its edges land on theirs, and a fit rarely crosses from one to the next."""
    step, out = SCAN[1] - SCAN[0], []
    for i, prm in enumerate(model.free):
        if prm.key != "overlay":
            continue
        points = [np.where(np.arange(len(x)) == i, value, x) for value in SCAN]
        res = [model.residual(xm) for xm in points]
        f = np.array([float(rm @ rm) for rm in res])
        low = np.r_[True, f[1:] <= f[:-1]] & np.r_[f[:-1] <= f[1:], True]  # local minima, the ends included
        for k in np.flatnonzero(low & (np.abs(SCAN - x[i]) > step)):
            out.append((points[k], _step_others(model, points[k], res[k], jac, [i])))
    return out


def _step_others(model: PartModel, xm: np.ndarray, rm: np.ndarray, jac: np.ndarray, held: list) -> np.ndarray:
    """Move the errors of ``xm`` (in place) other than ``held`` by one Gauss–Newton step from its weighted residual
    ``rm`` with ``jac`` (a nearby point's Jacobian), inside the bounds; returns the moved point's weighted residual."""
    rest = [j for j in range(len(xm)) if j not in held]
    xm[rest] = np.clip(xm[rest] + np.linalg.lstsq(jac[:, rest], -rm, rcond=None)[0], -BOUND, BOUND)
    return model.residual(xm)


def psf_metric(model: PartModel, x: np.ndarray) -> dict:
    """The design's task metric (the coded light's fraction in the task's pixels, mean over the measured bands and
    planes) of the error-free part, the measured pair and the fitted part (scaled as the measured one), and of the
    fitted part with its own light (``as_fitted_with_losses``: as the tolerance study judges it, the light it
    scatters out of the kernel lost); the model's parts on the finer grid the fit ends on."""
    task, cam = model.judge.task, model.judge.fine
    c = model.halves.index("coded")

    def value(coded) -> float:
        t = torch.as_tensor(np.ascontiguousarray(coded), dtype=torch.float64)
        return float(task.fractions(t, cam, model.dz, model.wl).mean())
    fitted = model.errors(x)
    return {"nominal": value(model.psfs(PartErrors(), fine=True)[c]), "as_measured": value(model.measured[c]),
            "as_fitted": value(model.psfs(fitted, fine=True)[c]),
            "as_fitted_with_losses": value(model.psfs(fitted, fine=True, scale=False)[c])}


def diagnose(measured, design_dir, budget=None, starts: int = STARTS, seed: int = 0, progress: bool = False,
             delivered: bool = False, device=None) -> dict:
    """The diagnosis of the part whose PSF pair is ``measured`` (a ``PSFPair``, e.g. ``PSFPair.load(psf_pair.npz)``)
    made from ``design_dir`` (a design folder, a mask set or a ``Design``): the ``diagnosis.json`` record
    (``lab.diagreport.assemble``). ``budget``: a budget file, a loaded budget or None (the shipped one);
    ``starts``: fits from the error-free part and ``starts − 1`` parts drawn from the budget with ``seed``;
    ``delivered``: also judge the fitted part through the task's shipped network (``lab.diagreport.delivered_metric``).
    A pair made from another design (its provenance's ``levels_sha256``) is refused before any work."""
    from doefab import validate as v
    from doefab.design.design import Design, design_folder_of
    from doefab.lab.diagreport import assemble, check_design, delivered_metric
    from doefab.tolerance.errors import load_budget

    v.number_in("starts", starts, 1, 100, integer=True)
    v.seed("seed", seed)
    b = budget if isinstance(budget, dict) else load_budget(budget)
    check_design(measured, design_dir if isinstance(design_dir, Design) else Design.load(design_folder_of(design_dir)))
    model = PartModel(design_dir, measured, b, device=device)
    t0 = time.perf_counter()
    bar = _bar(progress, model, starts)
    try:  # the line stays up, naming the step, until the record is whole: the uncertainty computes parts too
        got = fit(model, starts, seed)
        _step(bar, "uncertainty")
        cur = estimate(model, got, seed)
        seconds = time.perf_counter() - t0
        err = model.errors(got["x"])
        misfit = {"nominal": _plain_misfit(model, PartErrors(), fine=True),
                  "fitted": _plain_misfit(model, err, fine=True)}
        metric = psf_metric(model, got["x"])
        if delivered:
            _step(bar, "delivered quality through the network")
        net = delivered_metric(model, err, delivered)
    finally:
        if bar is not None:
            bar.close()
    return assemble(model, got, cur, misfit, metric, net,
                    {"seconds": seconds, "parts": model.evaluations, "starts": got["starts"]})


def _plain_misfit(model: PartModel, err: PartErrors, fine: bool = False) -> float:
    """The unweighted misfit of the part ``err`` (``fine``: on the finer grid)."""
    return float(np.sum((model.psfs(err, fine) - model.measured) ** 2))


def _step(bar, what: str) -> None:
    """Name the diagnosis's step on its progress line (``bar``: None without one)."""
    if bar is not None:
        bar.set_description(f"diagnose: {what}")


def _bar(progress: bool, model: PartModel, starts: int):
    """A progress line counting the parts computed and their rate, with no total: how many a fit needs is not known
    before it converges (``benchmarks/diagnose_coverage.py`` records 4224–9085 for 20 parts of 4 masks at 8
    starts, and a total from the fits' minimum steps fell short of that by about 4×, so its time left misled)."""
    if not progress:
        return None
    from tqdm import tqdm

    bar = tqdm(total=None, desc=f"diagnose: fit from {starts} starts", unit="part")
    model.tick = lambda: bar.update(1)
    return bar


def part_errors(diagnosis: dict) -> PartErrors:
    """The fitted part of a ``diagnosis.json`` record (SI units; corner rounding as the fit held it)."""
    e = diagnosis["errors"]
    ov = tuple((o["x"] * 1e-6, o["y"] * 1e-6) for o in e["overlay_um"])
    return PartErrors(depth_scale=tuple(float(d["value"]) for d in e["etch_depth_scale"]), overlay=ov,
                      edge_bias=e["edge_bias_um"]["value"] * 1e-6,
                      mount_shift=(e["mount_decenter_mm"]["x"] * 1e-3, e["mount_decenter_mm"]["y"] * 1e-3),
                      mount_rotation=math.radians(e["mount_rotation_deg"]["value"]),
                      axial_gap=e["axial_gap_mm"]["value"] * 1e-3,
                      corner_rounding=diagnosis["model"]["corner_rounding_um"] * 1e-6)


def fitted_pair(design_dir, errors, device=None):
    """The PSF pair (both halves, the design's task kernel) of the part ``errors`` (a ``PartErrors`` or a
    ``diagnosis.json`` record) at every band and plane of the design in ``design_dir``, on the design grid (1×)
    as the fit computed it: what a lab that recorded some bands or planes gives the networks."""
    from doefab.design.design import Design, design_folder_of
    from doefab.optics.psf import PSFPair
    from doefab.tolerance.judge import PSFJudge

    err = errors if isinstance(errors, PartErrors) else part_errors(errors)
    d = design_folder_of(design_dir) if not isinstance(design_dir, Design) else design_dir
    judge = PSFJudge(d, 1, margin=max(0.3e-3, 2 * abs(err.mount_shift[0])), device=device)
    with torch.no_grad():
        got = judge.psfs(err, halves=("coded", "uncoded"))
    dd = judge.design
    return PSFPair(coded=got["coded"].float(), uncoded=got["uncoded"].float(), wavelengths=tuple(dd.wavelengths),
                   depths=tuple(dd.depths), sensor_pitch=dd.camera.sensor_pitch, camera=dd.camera)
