"""The fitted errors' uncertainty, from the fit's local picture: its Jacobian and Gauss–Newton steps.

**Uncertainty** (``curvature``): the noise's covariance s²·J⁺W²J⁺ᵀ, J the central-difference Jacobian
(``jacobian``) of the weighted and whitened (W) residual vector in budget σ, s² = its misfit / (n − p); plus the
spread that the errors the fit holds give the fitted ones (``partmodel.held_errors``: ``HELD_DRAWS`` other parts
with the masks' rotations, the roughness and each held error drawn from the budget, their PSF changes less the
modelled mean, ± ``MEAN_SPREAD`` of it in turn, taken through −J⁺); a third of the fit's last steps on the finer
grid (``refine``) added in quadrature (what a finer grid still would move).

**Other fits**: each σ widened to half the distance to any other fit found (the fit's rivals and mirrors) that
the recordings do not tell apart from the best: its misfit within ``MIRROR_CHI2`` s² of the best's plus twice the
rms swing that the held errors' PSF changes give that difference (``tolerance``: a surface roughness of a few nm
can move the misfits of two far-apart fits further apart than the photon noise does).

**Identifiable**: the model responds to the error at all (``partmodel.Param.reason`` lists the ones it cannot), its
σ is below ``MAX_SIGMA`` budget σ (the recordings tell clearly more than the budget) and below the error's own
``Param.precision`` (an etch depth scale's σ at most 1 %: its 2σ interval within ±2 %, what a re-made mask's depth
is decided on), its |correlation| with every other fitted error is below ``MAX_CORRELATION`` (the recordings tell
them apart) and, for an overlay, its mirror fits worse by that ``tolerance`` (its sign is told).
"""

from __future__ import annotations

import numpy as np

from doefab.lab.partmodel import BOUND, HOLD_DRAWS, MEAN_SPREAD, STEP, Param, PartModel, held_errors

__all__ = ["jacobian", "refine", "curvature", "tolerance", "estimate", "MAX_CORRELATION", "MAX_SIGMA", "MIRROR_CHI2",
           "REFINE"]

MAX_CORRELATION = 0.95  # at or above it two errors are not told apart
MAX_SIGMA = 0.5  # an identifiable error's σ is below this many budget σ
MIRROR_CHI2 = 4.0  # another fit is told apart when it fits worse by this much (2σ), in units of s², plus twice the
# spread that the errors the fit holds give that rise (``tolerance``)
REFINE = 8  # Gauss–Newton steps at most on the finer grid


def jacobian(model: PartModel, x: np.ndarray, step: float = STEP) -> tuple[np.ndarray, np.ndarray]:
    """(weighted residual at ``x``, [n, p] its central-difference Jacobian in budget σ)."""
    r0 = model.residual(x)
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = step
        cols.append((model.residual(x + e) - model.residual(x - e)) / (2 * step))
    return r0, np.stack(cols, axis=1)


def refine(model: PartModel, x: np.ndarray, jac: np.ndarray, steps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Newton steps from ``x`` on the part model ``partmodel.FINE`` times finer than the design grid, with the
    design grid's Jacobian ``jac`` (the grids' Jacobians differ far less than their PSFs), each halved up to three
    times until it lowers the misfit: (the refined point, its weighted residual on the finer grid). The design
    grid's flat cells misplace the slivers a mask's overlay or bias cuts; the finer grid halves that error."""
    r = model.residual(x, fine=True)
    for _ in range(REFINE if steps is None else steps):
        delta = -np.linalg.lstsq(jac, r, rcond=None)[0]
        for scale in (1.0, 0.5, 0.25, 0.125):
            trial = np.clip(x + scale * delta, -BOUND, BOUND)
            rt = model.residual(trial, fine=True)
            if rt @ rt < r @ r:
                break
        else:
            break
        x, r = trial, rt
    return x, r


def curvature(params: list[Param], r: np.ndarray, jac: np.ndarray, mirrored=None, grid=None, x=None,
              others=(), held=None, whiten=None) -> dict:
    """{"sigma": [budget σ; inf where the PSFs do not respond], "correlation": [p, p], "identifiable": [bool],
    "reason": [str], "s2"} of the fitted errors from the residual ``r`` and Jacobian ``jac`` at the optimum, the
    overlays' mirror tests (``mirror``'s {"rise": in s², "change"}, or the rises alone; None: none made), the
    grid's share of the uncertainty (budget σ, added in quadrature; None: none) and the ``others`` fits found
    [(point, rise of the weighted misfit, change of the weighted residual or None)]: one that fits within
    ``tolerance`` of the optimum ``x`` lies inside every error's 2σ interval, so each σ is widened to half its
    distance from ``x`` where smaller. ``held``: [k, n] weighted changes of the PSFs that the errors the fit holds
    make (``held_errors``); the fitted errors' linear response to each, −J⁺·δ, adds its covariance (the unfitted
    errors' share: they move the fit alike in every pixel, which no per-pixel noise model holds), and they widen
    each ``tolerance``: a rival fit or a mirror is told apart only when it fits worse by more than they could
    swing the two misfits. ``whiten``: the whitening W of ``r`` and ``jac`` (``PartModel.whiten``; None: none),
    whose held errors' share ``held`` already holds: the noise's own share is then s²·J⁺W²J⁺ᵀ, not
    s²·(JᵀJ)⁻¹. An error is identifiable below ``MAX_SIGMA`` budget σ and its ``Param.precision``.
    Example: ``curvature(params, r, jac)["sigma"]`` → each error's σ, budget σ."""
    n, p = jac.shape
    s2 = float(r @ r) / max(n - p, 1)
    response = np.linalg.norm(jac, axis=0)
    live = response > 1e-9 * max(float(response.max(initial=0.0)), 1e-300)
    sigma, corr = np.full(p, np.inf), np.eye(p)
    if live.any():
        u, sv, vt = np.linalg.svd(jac[:, live], full_matrices=False)
        keep = sv > 1e-6 * sv.max()  # the directions the PSFs tell (JᵀJ's eigenvalues above 1e-12 of its largest)
        m = vt[keep].T / sv[keep]  # J⁺ = m·uᵀ
        if whiten is None:
            cov = s2 * m @ m.T
        else:  # W·u's columns: the noise (unit variance before whitening) seen through the whitened fit
            wu = np.stack([whiten(c) for c in u[:, keep].T], axis=1)
            cov = s2 * m @ (wu.T @ wu) @ m.T
        if held is not None and len(held):
            moved = -(np.asarray(held) @ u[:, keep] / sv[keep]) @ vt[keep]  # −J⁺δ per draw, [k, live]
            cov = cov + moved.T @ moved / len(moved)
        sl = np.sqrt(np.maximum(np.diag(cov), 0.0))
        sigma[live] = np.hypot(sl, 0.0 if grid is None else np.asarray(grid)[live])
        corr[np.ix_(live, live)] = np.clip(cov / np.maximum(np.outer(sl, sl), 1e-300), -1.0, 1.0)
    for xo, rise, change in others:
        if rise / s2 < tolerance(change, held, s2):
            sigma = np.maximum(sigma, np.abs(np.asarray(xo) - x) / 2)
    if isinstance(mirrored, dict):
        told = [tolerance(c, held, s2) for c in mirrored["change"]]
        mirrored = mirrored["rise"]
    elif mirrored is not None:
        told = [MIRROR_CHI2] * p
    ok, why = [], []
    for i in range(p):
        partner = max(((abs(corr[i, j]), params[j].label) for j in range(p) if j != i and live[j]), default=(0.0, ""))
        if not live[i]:
            reason = "the PSFs do not change with it"
        elif sigma[i] >= MAX_SIGMA:
            reason = (f"its uncertainty ({sigma[i]:.2g} budget σ) is not clearly below the budget's spread: the "
                      f"recordings do not pin it down")
        elif sigma[i] * params[i].sigma > params[i].precision:
            reason = (f"its uncertainty ({_shown(sigma[i] * params[i].sigma, params[i])}) is above the "
                      f"{_shown(params[i].precision, params[i])} a decision on it needs (more frames, more light or "
                      f"more bands shrink the noise's share)")
        elif partner[0] >= MAX_CORRELATION:
            reason = (f"it is correlated (|r| = {partner[0]:.2f}) with {partner[1]}: the recordings cannot tell the "
                      f"two apart")
        elif mirrored is not None and mirrored[i] < told[i]:
            reason = (f"its sign is not identified: the opposite overlay fits within 2σ (the misfit rises by "
                      f"{max(float(mirrored[i]), 0.0):.2g} s², under {told[i]:.2g}); its size is")
        else:
            reason = ""
        ok.append(not reason)
        why.append(reason)
    return {"sigma": sigma, "correlation": corr, "identifiable": ok, "reason": why, "s2": s2}


def _shown(value: float, prm: Param) -> str:
    """A σ of ``prm`` (SI) for people, in the unit ``Param.shown`` names."""
    unit, per = prm.shown
    return f"{value / prm.si * per:.2g} {unit}"


def tolerance(change, held, s2: float) -> float:
    """The rise of the weighted misfit (in s²) within which another fit is not told apart from the optimum:
    ``MIRROR_CHI2`` (2σ of the noise) plus twice the rms swing of that rise under the ``held`` errors' PSF changes
    (a change δ of the measured PSFs changes the rise by −2δ·``change``, the other fit's residual less the
    optimum's). Example: ``tolerance(None, None, 1.0)`` → 4.0."""
    if change is None or held is None or not len(held):
        return MIRROR_CHI2
    return MIRROR_CHI2 + 2.0 * float(np.sqrt(np.mean((2.0 * (np.asarray(held) @ change) / s2) ** 2)))


def estimate(model: PartModel, got: dict, seed: int = 0) -> dict:
    """``curvature``'s record of a fit (``diagnose.fit``'s ``got``) with the held errors' share (``held_errors``);
    ``"held"`` says what was drawn and how the held errors were modelled.
    Example: ``estimate(model, fit(model), seed=0)["sigma"]``."""
    held = held_errors(model, got["x"], seed=seed)
    cur = curvature(model.free, got["r"], got["jac"], got["mirror"], got["grid"], got["x"], got["others"], held,
                    model.whiten if model.basis is not None else None)
    cur["held"] = {"draws": len(held), "errors": ["mask rotations", "surface roughness"]
                   + [p.label for p in model.params if p.reason and p.sigma > 0],
                   "modelled": {"draws": HOLD_DRAWS if model.basis is not None else 0, "mean_spread": MEAN_SPREAD}}
    return cur
