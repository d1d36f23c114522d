"""The calibration's arithmetic on arrays: registration of a recorded PSF to the nominal one,
resampling onto the design's kernel, the light share, photon transfer, and the white-wall crosstalk ratios.

Conventions: frames are (H, W) digital numbers (DN), rows = y (row 0 top); a position is (row, column) in
pixels, sub-pixel where stated; a PSF window has its chief ray on pixel (K//2, K//2), as ``PSFPair``'s have.
"""

from __future__ import annotations

import numpy as np

from doefab.errors import DoefabError

__all__ = ["window", "register", "register_size", "extract", "normalise", "photon_transfer", "wall_ratios", "UPSAMPLE"]

UPSAMPLE = 100  # cross-correlation refined to 1/100 pixel
_PAD = 8  # pixels of frame kept around a kernel while it is shifted (the Fourier shift's wrap stays outside)


def window(frame: np.ndarray, centre, size: int) -> np.ndarray:
    """The ``size`` × ``size`` window of ``frame`` whose pixel (size//2, size//2) is frame pixel ``centre``
    (integers); zeros where it reaches beyond the frame."""
    h, w = frame.shape
    r0, c0 = int(centre[0]) - size // 2, int(centre[1]) - size // 2
    out = np.zeros((size, size))
    rs, cs = max(r0, 0), max(c0, 0)
    re, ce = min(r0 + size, h), min(c0 + size, w)
    if rs < re and cs < ce:
        out[rs - r0:re - r0, cs - c0:ce - c0] = frame[rs:re, cs:ce]
    return out


def register_size(k: int) -> int:
    """The side (pixels) of the frame crop :func:`register` cross-correlates for a K-pixel kernel: K plus K//2
    (at least 4) on each side."""
    return k + 2 * max(k // 2, 4)


def register(frame: np.ndarray, nominal: np.ndarray, upsample: int = UPSAMPLE, kernel: int | None = None) -> np.ndarray:
    """The chief ray's sub-pixel (row, column) in ``frame`` (a dark-subtracted recording, DN): where ``nominal``
    (the design's PSF, chief ray on its centre pixel) fits it best.

    The brightest pixel of the frame (smoothed over 3 × 3 against a hot pixel) is taken as the nominal's
    brightest, which places the chief ray to a pixel or so; then the frame is cropped around it
    (``register_size(kernel)``: the kernel plus half of it on each side) and cross-correlated with the nominal
    cropped or zero-padded to the same size (``skimage.registration.phase_cross_correlation`` without spectral
    whitening, refined ``upsample`` times): a part's PSF whose brightest lobe is not the design's is still found
    within ±K/2 pixels. Give ``nominal`` at least that size where the design puts light outside the kernel: a
    K × K nominal lacks the tails the crop holds, and they pull the match (a quarter pixel for a streak with a
    tenth of its light beyond K). ``kernel``: K (default: the nominal's size)."""
    from scipy.ndimage import uniform_filter
    from skimage.registration import phase_cross_correlation

    n = nominal.shape[-1]
    k = n if kernel is None else int(kernel)
    peak = np.array(np.unravel_index(np.argmax(uniform_filter(frame, 3, mode="constant")), frame.shape))
    nom_peak = np.array(np.unravel_index(np.argmax(uniform_filter(nominal, 3, mode="constant")), nominal.shape))
    coarse = peak - (nom_peak - n // 2)
    size = register_size(k)
    crop = window(frame, coarse, size)
    ref = window(nominal, (n // 2, n // 2), size)
    shift, _, _ = phase_cross_correlation(ref, crop, upsample_factor=upsample, normalization=None)
    return coarse - np.asarray(shift, dtype=np.float64)


def extract(frame: np.ndarray, chief, k: int) -> np.ndarray:
    """The K × K window of ``frame`` resampled (a Fourier shift: band-limited interpolation) so that the sub-pixel
    position ``chief`` (row, column) lands on pixel (K//2, K//2). Exact for a PSF sampled above Nyquist (its
    cut-off D / (λ f) below 1 / (2 · pitch)); an undersampled band keeps its aliasing's error (a few per cent of
    the light at 1.2× the Nyquist frequency)."""
    from scipy.ndimage import fourier_shift

    chief = np.asarray(chief, dtype=np.float64)
    whole = np.rint(chief)
    size = k + 2 * _PAD
    crop = window(frame, whole, size)
    moved = np.fft.ifft2(fourier_shift(np.fft.fft2(crop), whole - chief)).real
    return moved[_PAD:_PAD + k, _PAD:_PAD + k]


def normalise(psf: np.ndarray, share: float, what: str) -> np.ndarray:
    """``psf`` (DN) as energy fractions summing to ``share``: negative values (the dark's noise, the resampling's
    ringing) are set to 0 first, so a dark background adds about 0.4 σ per pixel (σ: its noise) to the sum and
    every pixel reads that much too dim; the frame checks refuse a recording where that exceeds 1 % of its light
    (``framechecks.MAX_NOISE_FLOOR``)."""
    p = np.clip(psf, 0.0, None)
    total = float(p.sum())
    if not np.isfinite(total) or total <= 0:
        raise DoefabError(f"{what}: no light in the kernel after the dark is subtracted: check that the source was "
                          f"on and the darks (or black_level) belong to these frames")
    return p * (share / total)


def photon_transfer(signal: np.ndarray, variance: np.ndarray, frames: int | None = None):
    """The conversion gain (DN per detected photon) from the photon-transfer relation ``variance = gain · signal
    + read variance``, the least-squares line's slope over the pixels given (signal: dark-subtracted DN; variance:
    from frame to frame, DN²); None when the fit finds no shot noise (a flat or too dim window).

    With ``frames`` (the number the variances came from): ``(gain, standard error)``, the error from each pixel's
    sample variance scattering by √(2 / (frames − 1)) of its expected value (gain · signal + read variance): a
    kernel window's slope rests on its few bright pixels, and from a few frames it scatters by tens of per cent.
    (Weighting the fit by those variances would lean on the dim pixels, whose noisy means bias the slope low.)"""
    s, v = np.asarray(signal, np.float64).ravel(), np.asarray(variance, np.float64).ravel()
    if s.size < 3 or float(np.ptp(s)) <= 0:
        return None
    gain, read2 = np.polyfit(s, v, 1)
    if not (np.isfinite(gain) and gain > 0):
        return None
    if frames is None:
        return float(gain)
    if frames < 2:
        return None
    expected = np.maximum(gain * s + max(float(read2), 0.0), 0.0)
    d = s - s.mean()
    var_gain = float(np.sum(d * d * 2 * expected ** 2 / (frames - 1))) / float(np.sum(d * d)) ** 2
    return float(gain), float(np.sqrt(var_gain))


def wall_ratios(plain_open, coded_open) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-column ``(α_l→r, α_r→l, se of α_l→r, se of α_r→l)`` from two white-wall pairs ``(plain view,
    coded view)`` (dark-subtracted DN, (rows, columns)): ``plain_open`` recorded with the coded half blocked (only the
    left, plain view lit: α_l→r = R* / (L* + R*)), ``coded_open`` with the plain half blocked (α_r→l = L* /
    (L* + R*)): Eq. 30–31 by :func:`doefab.imaging.crosstalk.calibrate_crosstalk`, averaged over rows. Each
    standard error is the row-to-row scatter of the pixels' ratios in that column, std / √rows."""
    from doefab.imaging.crosstalk import calibrate_crosstalk, ratio_standard_error

    pairs = [tuple(np.asarray(v, np.float64) for v in p) for p in (plain_open, coded_open)]
    a, b = calibrate_crosstalk(pairs[0], pairs[1])
    rows = pairs[0][0].shape[0]
    if rows < 2 or pairs[1][0].shape[0] < 2:
        raise DoefabError("white-wall frames need at least 2 rows for the ratios' standard errors")
    se = [ratio_standard_error(p[i], p[1 - i], axis=0).ravel() for p, i in zip(pairs, (1, 0))]
    return a.ravel(), b.ravel(), se[0], se[1]
