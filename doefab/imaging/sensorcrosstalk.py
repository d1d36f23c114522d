"""A real dual-pixel sensor's crosstalk (:class:`SensorCrosstalk`): dependent on the light's angle across and along
the split, varying from row to row and drifting between sessions, of which a per-column white-wall calibration
(:func:`doefab.imaging.crosstalk.simulate_calibration`, the paper's Eq. 30–31) captures only a part.

Example: ``SensorCrosstalk((0.05, 0.05), 0.02, seed=1).camera(rows, columns)`` is the ``DualPixelCrosstalk`` of
a crop of the sensor (its true ratios, and the pipeline's calibrated estimate).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.crossratios import check_pair
from doefab.imaging.crosstalk import DualPixelCrosstalk, _rows, simulate_calibration

__all__ = ["SensorCrosstalk", "SPOT_GROWTH", "ROW_SIGMA", "DRIFT_SIGMA", "MIN_RATIO"]


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

    def worst_determinant(self, columns: int = 65) -> tuple:
        """(1 − α_l→r − α_r→l, α_l→r, α_r→l) where Eq. 29's determinant is smallest over the calibrated region (every
        row, ``columns`` columns evenly across it, its edges included), at the calibration (no session's drift): how
        close the sensor's worst pixel comes to views that cannot be separated.

        Example: ``SensorCrosstalk((0.05, 0.05), 0.02).worst_determinant()[0]`` is about 0.82, below the
        centre's 0.9: the ratios rise toward the region's corners."""
        at = np.linspace(-0.5, 0.5, columns) * self.width_px
        rows = np.arange(self.width_px) - self.width_px / 2 + 0.5
        a, b = self.ratios(rows, at, session=None)
        det = 1.0 - a - b
        i = np.unravel_index(int(np.argmin(det)), det.shape)
        return float(det[i]), float(a[i]), float(b[i])

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
