"""Dual-pixel crosstalk (the paper's Eq. 29–31) and its exact inverse.

Eq. 29 mixes the left and right views: ``L* = (1 − a) L + b R``, ``R* = a L + (1 − b) R`` with
``a = α_l→r`` and ``b = α_r→l``; each ratio is a scalar or an array broadcastable to the images (per column
is what real dual-pixel sensors show). The inverse solves this 2 × 2 system exactly — its determinant is
``1 − a − b`` — instead of the paper's Eq. 32, whose printed denominator is not that of Eq. 29 (see
../shared/DESIGN-NOTES.md). A determinant near zero would amplify noise without bound, so the inverse refuses it;
every function refuses a pair whose determinant is ≤ 0 (:func:`check_pair`): each photodiode would collect as
much of the other half's light as of its own, which no dual-pixel sensor does.
Calibration (Eq. 30–31): with one aperture half blocked, a white wall's light reaches only one view, and the
fraction that lands on the other one is the ratio.

Crosstalk depends on the angle at which light reaches the sensor (the paper's Fig. 5), so the ratios change across
the sensor's columns: :func:`crosstalk_profile` models them as linear in the column's position, rising toward
one edge for l→r and toward the other for r→l. :func:`simulate_calibration` makes the two blocked-aperture
white-wall captures with sensor noise and estimates the ratios from them (Eq. 31, averaged over rows), so a
calibrated pipeline carries the calibration's own error.
"""

from __future__ import annotations

import numpy as np

from doefab.errors import DoefabError

__all__ = ["mix_crosstalk", "unmix_crosstalk", "calibrate_crosstalk", "MIN_DETERMINANT", "crosstalk_profile",
           "simulate_calibration", "DualPixelCrosstalk", "check_pair"]

MIN_DETERMINANT = 0.05  # 1 − a − b below this amplifies noise more than 20×: refused


def _ratio(name: str, a, like):
    """``a`` checked to be fractions in [0, 1), as the array type of ``like`` (torch tensor or numpy)."""
    vals = np.asarray(a.detach().cpu().numpy() if hasattr(a, "detach") else a, dtype=np.float64)
    if not np.all(np.isfinite(vals)):
        raise DoefabError(f"{name} holds NaN or infinite values: crosstalk ratios are fractions in [0, 1)")
    if np.any(vals < 0) or np.any(vals >= 1):
        raise DoefabError(f"{name} must hold crosstalk fractions in [0, 1), got values in "
                          f"[{vals.min():g}, {vals.max():g}]")
    if hasattr(like, "detach"):
        import torch

        return torch.as_tensor(vals, dtype=like.dtype, device=like.device)
    return vals


def check_pair(alpha_lr, alpha_rl, name: str = "alpha_lr, alpha_rl") -> None:
    """Refuse a ratio pair no dual-pixel sensor has. Each ratio is a fraction in [0, 1) of one view's light that
    lands on the other photodiode (``_ratio``), and Eq. 29's determinant ``1 − α_l→r − α_r→l`` must be > 0: at or
    below 0 each photodiode collects as large a share of the other half's light as of its own, so the views do
    not separate (at 0 they are one image; below, the photodiodes are swapped, not crossed)."""
    probe = np.zeros(1)
    a, b = _ratio(name.split(", ")[0], alpha_lr, probe), _ratio(name.split(", ")[-1], alpha_rl, probe)
    try:
        det = np.atleast_1d(1.0 - a - b)
    except ValueError:
        raise DoefabError(f"{name} must be scalars or per-column profiles of one length, got shapes "
                          f"{np.shape(alpha_lr)} and {np.shape(alpha_rl)}") from None
    if det.min() <= 0:
        i = int(np.argmin(det))
        where = f" at column {i}" if det.size > 1 else ""
        raise DoefabError(f"{name} = ({np.broadcast_to(a, det.shape)[i]:g}, {np.broadcast_to(b, det.shape)[i]:g})"
                          f"{where} is no dual-pixel crosstalk: 1 − α_l→r − α_r→l = {det[i]:.3g} ≤ 0, so each "
                          f"photodiode collects as much of the other half's light as of its own and the views do not "
                          f"separate; each ratio is the fraction of a view's light landing on the other photodiode, "
                          f"the two summing below 1 (measured sensors: a few per cent, e.g. (0.05, 0.05))")


def mix_crosstalk(left, right, alpha_lr, alpha_rl):
    """Seed Eq. 29: the recorded views ``(L*, R*)`` of clean views ``left``, ``right`` (numpy or torch)."""
    check_pair(alpha_lr, alpha_rl)
    a, b = _ratio("alpha_lr", alpha_lr, left), _ratio("alpha_rl", alpha_rl, left)
    return (1 - a) * left + b * right, a * left + (1 - b) * right


def unmix_crosstalk(left_star, right_star, alpha_lr, alpha_rl, min_determinant: float = MIN_DETERMINANT):
    """The exact inverse of Eq. 29: clean ``(L, R)`` from recorded ``(L*, R*)``.

    Raises DoefabError where ``1 − α_l→r − α_r→l < min_determinant`` (the inverse would amplify noise by more
    than ``1 / min_determinant``).
    """
    if not isinstance(min_determinant, (int, float)) or not 0 < min_determinant <= 1:
        raise DoefabError(f"min_determinant must be a number in (0, 1] (the smallest 1 − α_l→r − α_r→l accepted; "
                          f"default {MIN_DETERMINANT}), got {min_determinant!r}")
    a, b = _ratio("alpha_lr", alpha_lr, left_star), _ratio("alpha_rl", alpha_rl, left_star)
    det = 1 - a - b
    worst = float(det.min()) if hasattr(det, "min") else float(det)
    if worst < min_determinant:
        raise DoefabError(f"crosstalk inverse is near-singular: 1 − α_l→r − α_r→l = {worst:.3g} < {min_determinant:g} "
                          f"(noise would be amplified {1 / max(worst, 1e-12):.0f}×); recalibrate: ratios this large mean "
                          f"the views are not separated")
    left = ((1 - b) * left_star - b * right_star) / det
    right = ((1 - a) * right_star - a * left_star) / det
    return left, right


def calibrate_crosstalk(blocked_left_pair, blocked_right_pair, axis_mean: int | None = 0):
    """Eq. 30–31: crosstalk ratios from two white-wall captures, each with one aperture half blocked.

    Args:
        blocked_left_pair: ``(L*, R*)`` recorded with the LEFT aperture half (the DOE) blocked, as in the paper's
            Eq. 30: the right view then gets no light of its own (I_R = 0), so α_l→r = R* / (L* + R*) (Eq. 31).
            (The left aperture half images onto the right sub-pixels: coded = right view, uncoded = left.)
        blocked_right_pair: ``(L*, R*)`` with the RIGHT aperture half blocked (I_L = 0): α_r→l = L* / (L* + R*).
        axis_mean: average over this image axis (0: rows, giving one ratio per column, which is what dual-pixel
            sensors show); None keeps per-pixel ratios.
    Returns:
        ``(alpha_lr, alpha_rl)``.
    """
    def ratio(pair, num_index):
        l_s, r_s = (np.asarray(x, dtype=np.float64) for x in pair)
        if l_s.shape != r_s.shape:
            raise DoefabError(f"a calibration pair's two views differ in shape: {l_s.shape} vs {r_s.shape}")
        total = l_s + r_s
        if not np.all(np.isfinite(total)) or np.any(total <= 0):
            raise DoefabError("calibration captures must be finite and lit everywhere (a white wall, not black)")
        num = (l_s, r_s)[num_index]
        if axis_mean is not None:
            return num.mean(axis=axis_mean, keepdims=True) / total.mean(axis=axis_mean, keepdims=True)
        return num / total

    alpha_lr = ratio(blocked_left_pair, 1)
    alpha_rl = ratio(blocked_right_pair, 0)
    return alpha_lr, alpha_rl


def crosstalk_profile(columns, centre: float, slope: float, half_width: float):
    """Ratios at sensor ``columns`` (pixels from the sensor's centre column): ``centre + slope · x / half_width``
    clipped to [0, 0.499]; ``slope`` is the change from the centre to ``half_width`` columns away (the edge of
    the calibrated region; the paper's § 5.1: 3072 px wide)."""
    x = np.asarray(columns, np.float64)
    return np.clip(centre + slope * x / float(half_width), 0.0, 0.499)


def simulate_calibration(alpha_lr, alpha_rl, rows: int = 3072, noise="default", rng=0, level: float = 0.5):
    """(α̂_l→r, α̂_r→l) per column from two simulated white-wall captures of ``rows`` rows, each with one aperture
    half blocked (Eq. 30), exposed so the open half's view reaches ``level`` of full scale, with ``noise`` (a
    ``doefab.imaging.sensor`` preset name or model) on each recorded view, estimated by
    :func:`calibrate_crosstalk`. ``rng``: a seed or a ``numpy.random.Generator``."""
    import numbers

    from doefab import _validate
    from doefab.imaging.sensor import noise_model

    if isinstance(rows, bool) or not isinstance(rows, numbers.Integral) or not 1 <= rows <= 100_000:
        raise DoefabError(f"rows must be a whole number of sensor rows in 1..100000, got {rows!r}")
    if isinstance(level, bool) or not isinstance(level, numbers.Real) or not 0 < level <= 1:
        raise DoefabError(f"level must be the white wall's exposure as a fraction of full scale in (0, 1], got "
                          f"{level!r}")
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(_validate.seed("seed", rng))
    noise = noise_model(noise)
    check_pair(alpha_lr, alpha_rl)  # fractions of one length (or scalars) that leave the views separable
    probe = np.zeros(1)
    a, b = _ratio("alpha_lr", alpha_lr, probe), _ratio("alpha_rl", alpha_rl, probe)
    a, b = (np.atleast_1d(x).astype(np.float64).reshape(1, -1) for x in np.broadcast_arrays(a, b))
    white = np.full((int(rows), a.shape[1]), float(level))
    dark = np.zeros_like(white)
    pairs = []
    for left, right in ((white, dark), (dark, white)):  # left aperture half blocked → only the left view lit
        l_s, r_s = mix_crosstalk(left, right, a, b)
        pairs.append((np.clip(noise.apply(l_s, rng), 1e-9, None), np.clip(noise.apply(r_s, rng), 1e-9, None)))
    a_hat, b_hat = calibrate_crosstalk(pairs[0], pairs[1])
    return a_hat.ravel(), b_hat.ravel()


class DualPixelCrosstalk:
    """What a dual-pixel camera does to a pair of clean views, and what its pipeline undoes (the paper's § 5.1).

    ``record(coded, uncoded, noise, rng)``: the optical mix of Eq. 29 with the true per-column ratios (light
    lands on the wrong photodiode before it is counted), the sensor's noise, clipping to [0, 1], then — when the
    camera is calibrated — the exact unmix with the *estimated* ratios, a saturated photodiode's pixel staying
    saturated (full scale) in its view. Views are [..., H, W] arrays (numpy);
    ratios are scalars or per-column arrays of length W. The coded capture is the right view.
    """

    def __init__(self, alpha_lr, alpha_rl, estimate=None):
        check_pair(alpha_lr, alpha_rl)
        if estimate is not None:
            check_pair(estimate[0], estimate[1], "estimated alpha_lr, estimated alpha_rl")
        self.alpha_lr, self.alpha_rl = alpha_lr, alpha_rl
        self.estimate = estimate  # (α̂_l→r, α̂_r→l), or None: the pipeline leaves the mix in

    @classmethod
    def calibrated(cls, alpha_lr, alpha_rl, rows: int = 3072, noise="default", seed: int = 0,
                   level: float = 0.5) -> "DualPixelCrosstalk":
        """A camera with true ratios ``(alpha_lr, alpha_rl)`` (scalars or per-column profiles) whose pipeline
        unmixes with the ratios a simulated calibration estimated: two noisy white-wall captures of ``rows`` rows,
        each with one aperture half blocked (Eq. 30–31; ``noise``: a ``doefab.imaging.sensor`` preset or model).
        The estimate's own error stays in the captures, as it does in a user's pipeline."""
        estimate = simulate_calibration(alpha_lr, alpha_rl, rows, noise, seed, level)
        a, b = (np.atleast_1d(x).astype(np.float64) for x in np.broadcast_arrays(alpha_lr, alpha_rl))
        scalar = a.size == 1 and np.ndim(alpha_lr) == 0 and np.ndim(alpha_rl) == 0
        return cls(a if not scalar else float(a[0]), b if not scalar else float(b[0]),
                   estimate if not scalar else (float(estimate[0][0]), float(estimate[1][0])))

    def record(self, coded, uncoded, noise, rng):
        """(coded, uncoded) as the camera's pipeline delivers them, in [0, 1] (noise drawn coded first)."""
        left, right = mix_crosstalk(uncoded, coded, self.alpha_lr, self.alpha_rl)
        right = np.clip(noise.apply(right, rng), 0.0, 1.0)
        left = np.clip(noise.apply(left, rng), 0.0, 1.0)
        if self.estimate is not None:
            sat_l, sat_r = left >= 1.0, right >= 1.0
            left, right = unmix_crosstalk(left, right, *self.estimate)
            # a photodiode that saturated stays saturated: the unmix of a clipped value is no measurement (with
            # unequal ratios two saturated views unmix to values just below full scale that would pass as data)
            left = np.where(sat_l, 1.0, np.clip(left, 0.0, 1.0))
            right = np.where(sat_r, 1.0, np.clip(right, 0.0, 1.0))
        return right, left
