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

Crosstalk depends on the angle at which light reaches the sensor (the paper's Fig. 5). :class:`SensorCrosstalk` is
a sensor's true crosstalk: each aperture half's light forms a spot under a pixel's microlens, and the ratio is
the part of that spot beyond the photodiodes' boundary. The chief ray's angle across the split (the column's
place) moves both halves' spots the same way, so one ratio rises and the other falls, each half by its own law;
its angle along the split (the row's place) and across it widen the spots, raising both; the ratios vary from
row to row and drift between the calibration and a capture session. :func:`simulate_calibration` makes the two
blocked-aperture white-wall captures with sensor noise and estimates per-column ratios from them (Eq. 31,
averaged over rows), as the paper does: the rows' variation, the dependence on the row's place and the drift
stay in the calibrated captures (:meth:`SensorCrosstalk.residual`), with the calibration's own noise.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.crossratios import check_pair
from doefab.imaging.crossratios import ratio as _ratio

__all__ = ["mix_crosstalk", "unmix_crosstalk", "calibrate_crosstalk", "MIN_DETERMINANT", "SensorCrosstalk",
           "simulate_calibration", "DualPixelCrosstalk", "check_pair", "save_crosstalk"]

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
        if out.min() < 0 or out.max() >= 1:  # a view below black, or the blocked half's view the brighter
            i = np.unravel_index(int(np.argmax(np.abs(out - 0.5))), out.shape)
            raise DoefabError(f"the white-wall captures give {name} = {out[i]:.3g} (column {i[-1]}), outside [0, 1): "
                              f"the view of the blocked half must be the darker one and neither below black; check "
                              f"which half was blocked in each pair and the frames' black level")
        return out

    return ratio(blocked_left_pair, 1, "α_l→r"), ratio(blocked_right_pair, 0, "α_r→l")


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
    row its own, e.g. :meth:`SensorCrosstalk.ratios`); the estimate is one per column, whatever they are.
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
    a_hat, b_hat = calibrate_crosstalk(pairs[0], pairs[1])
    return a_hat.ravel(), b_hat.ravel()


class DualPixelCrosstalk:
    """What a dual-pixel camera does to a pair of clean views, and what its pipeline undoes (the paper's § 5.1).

    ``record(coded, uncoded, noise, rng)``: the optical mix of Eq. 29 with the true ratios (light
    lands on the wrong photodiode before it is counted), the sensor's noise, clipping to [0, 1], then — when the
    camera is calibrated — the exact unmix with the *estimated* ratios, a saturated photodiode's pixel staying
    saturated (full scale) in its view. Views are [..., H, W] arrays (numpy);
    ratios are scalars, per-column arrays of length W or [H, W] maps (a real sensor's true ratios:
    :meth:`SensorCrosstalk.camera`). The coded capture is the right view.

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
        column, all the calibration can estimate; :meth:`SensorCrosstalk.camera` is a real sensor's camera."""
        estimate = simulate_calibration(alpha_lr, alpha_rl, rows, noise, seed, level)
        a, b = (np.atleast_1d(x).astype(np.float64) for x in np.broadcast_arrays(alpha_lr, alpha_rl))
        scalar = a.size == 1 and np.ndim(alpha_lr) == 0 and np.ndim(alpha_rl) == 0
        return cls(a if not scalar else float(a[0]), b if not scalar else float(b[0]),
                   estimate if not scalar else (float(estimate[0][0]), float(estimate[1][0])))

    def record(self, coded, uncoded, noise="default", rng=0):
        """(coded, uncoded) as the camera's pipeline delivers them, in [0, 1] (noise drawn coded first). ``noise``:
        a ``doefab.imaging.sensor`` preset name (``"default"``, ``"authors"``, ``"none"``), model or ``Sensor``;
        ``rng``: a seed or a ``numpy.random.Generator``."""
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


SPOT_GROWTH = 0.05  # the spots' widening at the calibrated region's edge (assumed: see SensorCrosstalk)
ROW_SIGMA = 0.02  # rms row-to-row relative change of each ratio (assumed)
DRIFT_SIGMA = 0.03  # rms relative change of each ratio between the calibration and a capture session (assumed)
MIN_RATIO = 1e-4  # a ratio below this counts as this (where the spot model's distance is finite)
_ROW_PERIOD = 1 << 17  # rows of a sensor's fixed row pattern: more than any calibrated width


def _pixels(name: str, values) -> np.ndarray:
    """``values`` as a 1-D array of finite pixel positions."""
    try:
        x = np.atleast_1d(np.asarray(values, dtype=np.float64))
    except (TypeError, ValueError):
        x = np.array([np.nan])
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        raise DoefabError(f"{name} must be a list of finite pixel positions from the sensor's centre (e.g. "
                          f"[-1.5, -0.5, 0.5, 1.5]), got {values!r}")
    return x


@dataclass(frozen=True)
class SensorCrosstalk:
    """The true crosstalk of a dual-pixel sensor: what its captures are mixed by, of which a per-column white-wall
    calibration (Eq. 30–31) captures only a part.

    Light through each aperture half forms a spot on its own photodiode under a pixel's microlens; the ratio is the
    part of that spot beyond the photodiodes' boundary, ``Φ(z)`` (Φ: the normal distribution function; ``z``: the
    spot centre's distance from the boundary in spot widths, negative). The field position enters through the
    chief ray's angle, whose tangent grows in proportion to the distance from the sensor's centre (``u``, ``v``:
    the column and the row from the centre in units of half the calibrated width ``width_px``):

    - across the split, the chief ray moves both halves' spots the same way: ``z_l→r = Φ⁻¹(centre[0]) + k_l·u``,
      ``z_r→l = Φ⁻¹(centre[1]) − k_r·u``, each half with its own ``k``: α_l→r reaches ``centre[0] + slope`` and
      α_r→l ``centre[1] − slope`` at the calibrated edge (u = 1) of the centre row;
    - the obliquity of the light along both axes widens the spots, ``z / (1 + spot_growth·(u² + v²))``, raising
      both ratios toward the region's edges: along a column too, where a per-column calibration takes their mean;
    - each row's microlenses sit a little off their photodiodes: α_l→r × (1 + ρ), α_r→l × (1 − ρ), ρ drawn per
      row (rms ``row_sigma``; the sensor's fixed pattern, the same at the calibration and in every capture);
    - between the calibration and a capture session (temperature and focus move the microlenses' focus and the
      exit pupil) each ratio changes by a factor 1 + δ, δ drawn per session and half (rms ``drift_sigma``).

    ``centre``, ``slope`` and ``width_px`` are the tolerance budget's ``[sensor]`` values (the paper calibrates the
    central 3072 × 3072 pixels). ``spot_growth`` = 0.05, ``row_sigma`` = 0.02 and ``drift_sigma`` = 0.03 are
    assumptions, not measurements: the prototype's chief ray meets the calibrated region's edge at about 9°
    (1536 px × 5.4 µm = 8.3 mm off axis, the exit pupil some 50 mm away), where a microlens spot a few per cent
    wider is plausible; a few per cent of the ratio from row to row and from day to day are what a per-row
    calibration repeated on another day would show. ``seed`` draws the row pattern and the sessions' drift.
    """

    centre: tuple = (0.05, 0.05)
    slope: float = 0.0
    spot_growth: float = SPOT_GROWTH
    row_sigma: float = ROW_SIGMA
    drift_sigma: float = DRIFT_SIGMA
    width_px: int = 3072
    seed: int = 0

    def __post_init__(self):
        from doefab import validate as _validate

        try:
            a, b = (float(x) for x in self.centre)
        except (TypeError, ValueError):
            raise DoefabError(f"centre must be the pair (α_l→r, α_r→l) of ratios at the sensor's centre, got "
                              f"{self.centre!r}; e.g. (0.05, 0.05)") from None
        check_pair(a, b, "centre α_l→r, centre α_r→l")
        for name, hi in (("slope", 0.5), ("spot_growth", 1.0), ("row_sigma", 0.2), ("drift_sigma", 0.2)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not 0 <= v <= hi:
                raise DoefabError(f"{name} must be a fraction in [0, {hi:g}], got {v!r}; e.g. "
                                  f"{getattr(SensorCrosstalk, name):g} (the default)")
        w = self.width_px
        if isinstance(w, bool) or not isinstance(w, numbers.Integral) or not 16 <= w <= 100_000:
            raise DoefabError(f"width_px must be the calibrated region's width, a whole number of pixels in "
                              f"16..100000, got {w!r}; e.g. 3072 (the paper's)")
        _validate.seed("seed", self.seed)

    def ratios(self, rows, columns, session: int | None = 0) -> tuple:
        """(α_l→r, α_r→l) as [len(rows), len(columns)] maps at sensor ``rows`` and ``columns`` (pixels from the
        centre), in capture ``session`` (its drift drawn from the seed; None: at the calibration, from which the
        drift is counted)."""
        from scipy.special import ndtr, ndtri

        r, c = _pixels("rows", rows), _pixels("columns", columns)
        u, v = c[None, :] / (self.width_px / 2), r[:, None] / (self.width_px / 2)
        a0, b0 = (min(max(float(x), MIN_RATIO), 1 - MIN_RATIO) for x in self.centre)
        za, zb = ndtri(a0), ndtri(b0)
        edge = 1.0 + self.spot_growth  # the spots' widening at u = 1 on the centre row, where the slope is met
        ka = ndtri(min(a0 + self.slope, 1 - MIN_RATIO)) * edge - za
        kb = zb - ndtri(max(b0 - self.slope, MIN_RATIO)) * edge
        widen = 1.0 + self.spot_growth * (u * u + v * v)
        rho = np.random.default_rng(np.random.SeedSequence([self.seed, 37])).normal(0.0, self.row_sigma, _ROW_PERIOD)
        rho = rho[np.floor(r).astype(np.int64) % _ROW_PERIOD][:, None]
        da, db = self.drift(session) if session is not None else (0.0, 0.0)
        a = ndtr((za + ka * u) / widen) * (1 + rho) * (1 + da)
        b = ndtr((zb - kb * u) / widen) * (1 - rho) * (1 + db)
        return np.clip(a, 0.0, 0.999), np.clip(b, 0.0, 0.999)

    def drift(self, session: int) -> np.ndarray:
        """(δ_l→r, δ_r→l): each ratio's relative change in capture ``session`` since the calibration."""
        from doefab import validate as _validate

        s = _validate.seed("session", session)
        return np.random.default_rng(np.random.SeedSequence([self.seed, 31, s])).normal(0.0, self.drift_sigma, 2)

    def calibrate(self, columns, rows: int = 3072, noise="default", rng=0, level: float = 0.5) -> tuple:
        """Per-column (α̂_l→r, α̂_r→l) at ``columns`` from the white-wall calibration (:func:`simulate_calibration`)
        of ``rows`` rows spread evenly over the calibrated height, made before any capture session."""
        n = _rows(rows)
        at = ((np.arange(n) + 0.5) / n - 0.5) * self.width_px
        return simulate_calibration(*self.ratios(at, columns, session=None), n, noise, rng, level)

    def camera(self, rows, columns, noise="default", session: int = 0, calibration_rows: int = 3072, rng=0,
               level: float = 0.5, calibrated: bool = True) -> "DualPixelCrosstalk":
        """The :class:`DualPixelCrosstalk` of a crop at ``rows`` × ``columns`` (pixels from the centre) in capture
        ``session``: mixed by the true ratios there and, ``calibrated``, unmixed with the per-column estimate of
        a calibration of ``calibration_rows`` rows with the sensor's ``noise`` (seeded by ``rng``)."""
        a, b = self.ratios(rows, columns, session)
        estimate = self.calibrate(columns, calibration_rows, noise, rng, level) if calibrated else None
        return DualPixelCrosstalk(a, b, estimate)

    def residual(self, rows: int = 3072, noise="none", sessions: int = 8, grid: int = 64, rng=0) -> tuple:
        """(l→r, r→l) RMS of true − calibrated ratio over the calibrated region (a ``grid`` × ``grid`` lattice of
        its pixels) and capture sessions 0 … ``sessions`` − 1: what the per-column calibration of ``rows`` rows
        leaves in the captures (``noise`` "none": the part no number of calibration rows removes)."""
        from doefab import validate as _validate

        n_s = _validate.number_in("sessions", sessions, 1, 10_000, integer=True)
        at = ((np.arange(_validate.number_in("grid", grid, 1, 4096, integer=True)) + 0.5) / grid - 0.5) * self.width_px
        estimate = np.stack(self.calibrate(at, rows, noise, rng))[:, None, :]
        gaps = np.array([np.stack(self.ratios(at, at, s)) - estimate for s in range(n_s)])
        return tuple(float(x) for x in np.sqrt(np.mean(gaps * gaps, axis=(0, 2, 3))))
