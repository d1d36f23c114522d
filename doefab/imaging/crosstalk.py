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

Crosstalk depends on the angle at which light reaches the sensor (the paper's Fig. 5).
``sensorcrosstalk.SensorCrosstalk`` is a sensor's true crosstalk: each aperture half's light forms a spot under a
pixel's microlens, and the ratio is the part of that spot beyond the photodiodes' boundary. The chief ray's angle
across the split (the column's place) moves both halves' spots the same way, so one ratio rises and the other
falls, each half by its own law; its angle along the split (the row's place) and across it widen the spots,
raising both; the ratios vary from row to row and drift between the calibration and a capture session.
:func:`simulate_calibration` makes the two
blocked-aperture white-wall captures with sensor noise and estimates per-column ratios from them (Eq. 31,
averaged over rows), as the paper does: the rows' variation, the dependence on the row's place and the drift
stay in the calibrated captures (``SensorCrosstalk.residual``), with the calibration's own noise.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.crossratios import check_pair
from doefab.imaging.crossratios import ratio as _ratio

__all__ = ["mix_crosstalk", "unmix_crosstalk", "calibrate_crosstalk", "MIN_DETERMINANT", "simulate_calibration",
           "DualPixelCrosstalk", "check_pair", "save_crosstalk", "ratio_standard_error", "calibration_scatter"]

MIN_DETERMINANT = 0.05  # 1 − a − b below this amplifies noise more than 20×: refused


def _same_views(left, right, names: str) -> None:
    """The two views of one capture: arrays of one shape (numpy, torch or nested lists), or two numbers."""
    shapes = [tuple(np.shape(v)) for v in (left, right)]
    if shapes[0] != shapes[1]:
        raise DoefabError(f"{names} must be the two views of one capture, arrays of the same shape, got shapes "
                          f"{shapes[0]} and {shapes[1]}")


def mix_crosstalk(left, right, alpha_lr, alpha_rl):
    """The paper's Eq. 29: the recorded views ``(L*, R*)`` of clean views ``left``, ``right`` (numpy or torch, of
    one shape; the ratios are fractions, scalars or arrays broadcastable to the views).

    Example:

        >>> import numpy as np, doefab
        >>> left, right = doefab.mix_crosstalk(np.ones(4), np.zeros(4), 0.1, 0.05)  # α_l→r = 0.1, α_r→l = 0.05
        >>> left.tolist(), right.tolist()  # 0.9 of the left view's light stays, 0.1 crosses over
        ([0.9, 0.9, 0.9, 0.9], [0.1, 0.1, 0.1, 0.1])
    """
    _same_views(left, right, "left and right")
    check_pair(alpha_lr, alpha_rl)
    a, b = _ratio("alpha_lr", alpha_lr, left), _ratio("alpha_rl", alpha_rl, left)
    return (1 - a) * left + b * right, a * left + (1 - b) * right


def unmix_crosstalk(left_star, right_star, alpha_lr, alpha_rl, min_determinant: float = MIN_DETERMINANT):
    """The exact inverse of Eq. 29: clean ``(L, R)`` from recorded ``(L*, R*)``.

    Raises DoefabError where ``1 − α_l→r − α_r→l < min_determinant`` (the inverse would amplify noise by more
    than ``1 / min_determinant``).

    Example:

        >>> import numpy as np, doefab
        >>> left, right = doefab.mix_crosstalk(np.array([0.6]), np.array([0.2]), 0.1, 0.05)  # Eq. 29
        >>> [round(float(v[0]), 6) for v in doefab.unmix_crosstalk(left, right, 0.1, 0.05)]
        [0.6, 0.2]
    """
    if not isinstance(min_determinant, (int, float)) or not 0 < min_determinant <= 1:
        raise DoefabError(f"min_determinant must be a number in (0, 1] (the smallest 1 − α_l→r − α_r→l accepted; "
                          f"default {MIN_DETERMINANT}), got {min_determinant!r}")
    _same_views(left_star, right_star, "left_star and right_star")
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


def calibrate_crosstalk(blocked_left_pair, blocked_right_pair, axis_mean: int | None = 0, strict: bool = True):
    """Eq. 30–31: crosstalk ratios from two white-wall captures, each with one aperture half blocked.

    Args:
        blocked_left_pair: ``(L*, R*)`` recorded with the LEFT aperture half (the DOE) blocked, as in the paper's
            Eq. 30: the right view then gets no light of its own (I_R = 0), so α_l→r = R* / (L* + R*) (Eq. 31).
            (The left aperture half images onto the right sub-pixels: coded = right view, uncoded = left.)
        blocked_right_pair: ``(L*, R*)`` with the RIGHT aperture half blocked (I_L = 0): α_r→l = L* / (L* + R*).
        axis_mean: average over this image axis (0: rows, giving one ratio per column, which is what dual-pixel
            sensors show); None keeps per-pixel ratios.
        strict: refuse captures that give a ratio of 1 or more, or one below 0 by more than five standard errors
            of its column's rows (a view below black, or the halves swapped); a ratio below 0 within its noise
            reads 0. False (a simulation): every ratio is cut to [0, 1).
    Returns:
        ``(alpha_lr, alpha_rl)``, fractions in [0, 1).

    Example:

        >>> import numpy as np, doefab
        >>> left_blocked = (np.full((4, 3), 0.45), np.full((4, 3), 0.05))  # (L*, R*): R* is all crosstalk
        >>> right_blocked = (np.full((4, 3), 0.02), np.full((4, 3), 0.48))
        >>> a_lr, a_rl = doefab.calibrate_crosstalk(left_blocked, right_blocked)  # one ratio per column
        >>> a_lr.round(3).tolist(), a_rl.round(3).tolist()
        ([[0.1, 0.1, 0.1]], [[0.04, 0.04, 0.04]])
    """
    def ratio(pair, num_index, name):
        l_s, r_s = (np.asarray(x, dtype=np.float64) for x in pair)
        _same_views(l_s, r_s, "a calibration pair's views")
        num, total = (l_s, r_s)[num_index], l_s + r_s
        if axis_mean is not None:  # a dark-subtracted view's pixels scatter about 0: their mean is the estimate
            num, total = num.mean(axis=axis_mean, keepdims=True), total.mean(axis=axis_mean, keepdims=True)
        if not np.all(np.isfinite(total)) or np.any(total <= 0):
            raise DoefabError("calibration captures must be finite and lit everywhere (a white wall, not black)")
        out = num / total
        if not strict:
            return np.clip(out, 0.0, np.nextafter(1.0, 0.0))
        low = np.zeros_like(out)  # below it a ratio is not noise about 0
        if axis_mean is not None and l_s.shape[axis_mean] > 1:
            low = -5 * ratio_standard_error((l_s, r_s)[num_index], (l_s, r_s)[1 - num_index], axis_mean)
        bad = (out >= 1) | (out < np.nan_to_num(low))
        if bad.any():  # a view below black, or the blocked half's view the brighter
            i = np.unravel_index(int(np.argmax(bad)), out.shape)
            where = f"column {i[-1]}" if axis_mean is not None else f"row {i[0]}, column {i[-1]}"
            raise DoefabError(f"the white-wall captures give {name} = {out[i]:.3g} ({where}), outside [0, 1): the "
                              f"view of the blocked half must be the darker one and neither below black; check which "
                              f"half was blocked in each pair and the frames' black level")
        return np.clip(out, 0.0, np.nextafter(1.0, 0.0))

    return ratio(blocked_left_pair, 1, "α_l→r"), ratio(blocked_right_pair, 0, "α_r→l")


def ratio_standard_error(view, other, axis: int = 0) -> np.ndarray:
    """The standard error of a white-wall ratio ``view / (view + other)`` averaged along ``axis`` (0: rows): its
    pixels' scatter along it, std / √n (ddof 1), a pixel without light left out; the result keeps ``axis`` (size 1).

    Example: ``ratio_standard_error(np.array([[0.1], [0.3]]), np.array([[0.9], [0.7]]))`` is [[0.1]]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.asarray(view, np.float64) / (np.asarray(view, np.float64) + np.asarray(other, np.float64))
    per = np.where(np.isfinite(per), per, np.nan)
    return np.nanstd(per, axis=axis, ddof=1, keepdims=True) / np.sqrt(per.shape[axis])


def calibration_scatter(alpha: float, rows: int, level: float, full_well_e: float, read_noise_e: float) -> float:
    """The relative standard error of one column's ratio ``alpha`` from a white-wall calibration (Eq. 30–31,
    :func:`simulate_calibration`) of ``rows`` rows exposed to ``level`` of full scale on a sensor of ``full_well_e``
    electrons at value 1 and ``read_noise_e`` electrons rms: the ratio of the rows' means, by the delta method,
    ``√(α(1 − α)T + σ²(1 − 2α + 2α²)) / (T √rows) / α`` with ``T = level · full_well_e`` (the open half's
    electrons, both views together; shot noise binomial-like, the read noise in both views). Where few electrons
    reach the blocked view the simulation's estimate, cut at 0, scatters somewhat less.

    Example: ``calibration_scatter(0.05, 3072, 0.5, 25_000, 3.0)`` is about 0.0007 (the paper's calibration);
    ``calibration_scatter(0.05, 1, 0.01, 25_000, 3.0)`` about 0.36 (one dim row)."""
    total = float(level) * float(full_well_e)
    a, var_read = float(alpha), float(read_noise_e) ** 2
    if not (0 < a < 1 and total > 0 and rows >= 1):
        raise DoefabError(f"calibration_scatter needs a ratio in (0, 1), a lit calibration and rows ≥ 1, got "
                          f"alpha={alpha!r}, level × full well = {total!r} e, rows={rows!r}")
    sd = math.sqrt(a * (1 - a) * total + var_read * (1 - 2 * a + 2 * a * a)) / (total * math.sqrt(rows))
    return sd / a


def save_crosstalk(path, alpha_lr, alpha_rl, se_lr, se_rl, meta: dict | None = None):
    """Write ``crosstalk.json`` atomically: per-column ratios α_l→r, α_r→l and their standard errors, plus ``meta``
    (:mod:`doefab.imaging.crosstalkfile`); :meth:`DualPixelCrosstalk.load` reads it. Returns the path."""
    from doefab.imaging.crosstalkfile import save_crosstalk as save

    return save(path, alpha_lr, alpha_rl, se_lr, se_rl, meta)


def _rows(rows) -> int:
    """``rows`` checked to be a whole number of sensor rows a calibration averages."""
    if isinstance(rows, bool) or not isinstance(rows, numbers.Integral) or not 1 <= rows <= 100_000:
        raise DoefabError(f"rows must be a whole number of sensor rows in 1..100000, got {rows!r} (the paper "
                          f"calibrates 3072)")
    return int(rows)


def _noise_and_rng(noise, rng):
    """``noise`` as a model (a ``doefab.imaging.sensor`` preset name, model or ``Sensor``: ``noise_model``) and
    ``rng`` as a ``numpy.random.Generator`` (a seed, or one), each checked."""
    from doefab import validate as _validate
    from doefab.imaging.sensor import noise_model

    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(_validate.seed("seed", rng))
    return noise_model(noise), rng


def simulate_calibration(alpha_lr, alpha_rl, rows: int = 3072, noise="default", rng=0, level: float = 0.5):
    """(α̂_l→r, α̂_r→l) per column from two simulated white-wall captures of ``rows`` rows, each with one aperture
    half blocked (Eq. 30), exposed so the open half's view reaches ``level`` of full scale, with ``noise`` (a
    ``doefab.imaging.sensor`` preset name or model) on each recorded view, estimated by
    :func:`calibrate_crosstalk`. The true ratios are scalars, per-column profiles or [rows, columns] maps (each
    row its own, e.g. ``SensorCrosstalk.ratios``); the estimate is one per column, whatever they are.
    ``rng``: a seed or a ``numpy.random.Generator``.

    Example:

        >>> import doefab
        >>> a_lr, a_rl = doefab.simulate_calibration(0.1, 0.05, rows=512, rng=0)  # the true ratios, a scalar each
        >>> round(float(a_lr.mean()), 3), round(float(a_rl.mean()), 3)
        (0.1, 0.05)
    """
    rows = _rows(rows)
    if isinstance(level, bool) or not isinstance(level, numbers.Real) or not 0 < level <= 1:
        raise DoefabError(f"level must be the white wall's exposure as a fraction of full scale in (0, 1], got "
                          f"{level!r}")
    noise, rng = _noise_and_rng(noise, rng)
    check_pair(alpha_lr, alpha_rl)  # fractions of one shape (or scalars) that leave the views separable
    probe = np.zeros(1)
    a, b = _ratio("alpha_lr", alpha_lr, probe), _ratio("alpha_rl", alpha_rl, probe)
    a, b = (np.atleast_1d(x).astype(np.float64) for x in np.broadcast_arrays(a, b))
    if a.ndim == 1:
        a, b = a.reshape(1, -1), b.reshape(1, -1)
    if a.ndim != 2 or a.shape[0] not in (1, rows):
        raise DoefabError(f"alpha_lr, alpha_rl of shape {a.shape} are no ratios of a {rows}-row calibration: give "
                          f"scalars, per-column profiles or [rows, columns] maps with rows = {rows}")
    white = np.full((rows, a.shape[1]), float(level))
    dark = np.zeros_like(white)
    pairs = []
    for left, right in ((white, dark), (dark, white)):  # left aperture half blocked → only the left view lit
        l_s, r_s = mix_crosstalk(left, right, a, b)
        pairs.append((noise.apply(l_s, rng), noise.apply(r_s, rng)))  # unclipped: a dark view's noise averages out
    a_hat, b_hat = calibrate_crosstalk(pairs[0], pairs[1], strict=False)  # a ratio near 0 may read below 0
    return a_hat.ravel(), b_hat.ravel()


class DualPixelCrosstalk:
    """What a dual-pixel camera does to a pair of clean views, and what its pipeline undoes (the paper's § 5.1).

    ``record(coded, uncoded, noise, rng)``: the optical mix of Eq. 29 with the true ratios (light
    lands on the wrong photodiode before it is counted), the sensor's noise, clipping to [0, 1], then — when the
    camera is calibrated — the exact unmix with the *estimated* ratios, a saturated photodiode's pixel staying
    saturated (full scale) in its view. Views are [..., H, W] arrays (numpy);
    ratios are scalars, per-column arrays of length W or [H, W] maps (a real sensor's true ratios:
    ``SensorCrosstalk.camera``). The coded capture is the right view.

    Example:

        >>> import numpy as np, doefab
        >>> xt = doefab.DualPixelCrosstalk(0.1, 0.05)  # α_l→r, α_r→l; no estimate: the pipeline leaves the mix in
        >>> coded, uncoded = xt.record(np.full((4, 4), 0.6), np.full((4, 4), 0.2), noise="none")
        >>> round(float(coded[0, 0]), 3), round(float(uncoded[0, 0]), 3)  # 0.1·0.2 + 0.95·0.6, 0.9·0.2 + 0.05·0.6
        (0.59, 0.21)
    """

    def __init__(self, alpha_lr, alpha_rl, estimate=None):
        check_pair(alpha_lr, alpha_rl)
        if estimate is not None:
            check_pair(estimate[0], estimate[1], "estimated alpha_lr, estimated alpha_rl")
        self.alpha_lr, self.alpha_rl = alpha_lr, alpha_rl
        self.estimate = estimate  # (α̂_l→r, α̂_r→l), or None: the pipeline leaves the mix in
        self.standard_error = None  # (se of α̂_l→r, se of α̂_r→l) per column, for a camera read from crosstalk.json

    @classmethod
    def load(cls, path) -> "DualPixelCrosstalk":
        """The camera as calibrated, from ``crosstalk.json`` (written by ``doefab calibrate``; checked by
        :func:`doefab.imaging.crosstalkfile.read_crosstalk`): the per-column ratios are both its mix and its
        pipeline's estimate, ``DualPixelCrosstalk(a, b, estimate=(a, b))``; ``standard_error`` holds their
        per-column standard errors."""
        from doefab.imaging.crosstalkfile import read_crosstalk

        p, _ = read_crosstalk(path)
        cam = cls(p["alpha_lr"], p["alpha_rl"], estimate=(p["alpha_lr"], p["alpha_rl"]))
        cam.standard_error = (p["alpha_lr_se"], p["alpha_rl_se"])
        return cam

    @classmethod
    def calibrated(cls, alpha_lr, alpha_rl, rows: int = 3072, noise="default", seed: int = 0,
                   level: float = 0.5) -> "DualPixelCrosstalk":
        """A camera with true ratios ``(alpha_lr, alpha_rl)`` (scalars or per-column profiles) whose pipeline
        unmixes with the ratios a simulated calibration estimated: two noisy white-wall captures of ``rows`` rows,
        each with one aperture half blocked (Eq. 30–31; ``noise``: a ``doefab.imaging.sensor`` preset or model).
        The estimate's own error stays in the captures, as it does in a user's pipeline. The true ratios are per
        column, all the calibration can estimate; ``SensorCrosstalk.camera`` is a real sensor's camera."""
        estimate = simulate_calibration(alpha_lr, alpha_rl, rows, noise, seed, level)
        a, b = (np.atleast_1d(x).astype(np.float64) for x in np.broadcast_arrays(alpha_lr, alpha_rl))
        scalar = a.size == 1 and np.ndim(alpha_lr) == 0 and np.ndim(alpha_rl) == 0
        return cls(a if not scalar else float(a[0]), b if not scalar else float(b[0]),
                   estimate if not scalar else (float(estimate[0][0]), float(estimate[1][0])))

    def record(self, coded, uncoded, noise="default", rng=0):
        """(coded, uncoded) as the camera's pipeline delivers them, in [0, 1] (noise drawn coded first). ``noise``:
        a ``doefab.imaging.sensor`` preset name (``"default"``, ``"authors"``, ``"none"``), model or ``Sensor``;
        ``rng``: a seed or a ``numpy.random.Generator`` (a seed, 0 by default, draws the same noise every call:
        pass one generator to successive calls for fresh noise each time)."""
        noise, rng = _noise_and_rng(noise, rng)
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
