"""Every frame of a recording read once and checked: readable, one size, darks of that size, the channels the
recording says, at least the kernel, not saturated, and enough light for the kernel.

Enough light is judged on the signal-to-noise ratio, which needs no camera gain (digital numbers are not photons):

- the signal is the frames' mean less the dark frames' mean (without darks: the file's ``black_level``, else a raw's
  own level for each of R, G, B, :func:`frame_black`), in
  the kernel-sized window around the brightest pixel (3 × 3 smoothed, so a hot pixel does not pick it);
- its noise is measured from the frames themselves: the frame-to-frame variance of each pixel (two frames or more;
  shot, read and dark noise alike), divided by the number of frames, plus the dark mean's own; a single frame gets
  the robust scatter (1.4826 × MAD) of its background outside the window, or the darks' variance, which hold no
  shot noise (optimistic);
- ``MIN_KERNEL_SNR`` = 100: the window's summed signal over the noise of that sum. The calibration normalises
  each half to its share of the light, so the sum's relative error (1 % here) is the error of every pixel's
  scale; the diagnosis compares PSFs at the per-cent level;
- ``MIN_PEAK_SNR`` = 20: the brightest pixel over the median pixel noise of the window. The registration
  cross-correlates the PSF with the design's: at 20 the peak's 5 % noise keeps it well inside a pixel.
- ``MAX_NOISE_FLOOR`` = 1 %: a PSF holds no negative light, so the calibration sets the window's negative pixels
  (the background's noise) to zero before it normalises: each background pixel of noise σ then adds about 0.4 σ,
  and over a K × K window that sum can exceed the sum's own noise (σ K) K-fold — at the kernel SNR of 100 a 95-px
  window would gain 38 % of false light, and every pixel of the PSF would read that much too dim. The light that
  zeroing adds to the measured window, Σ max(−pixel, 0), must stay below this share of its total (it falls as
  1/√frames, as the SNRs rise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.lab.frames import frame_format, raw_black_level, raw_saturated, read_frame, stated_white_level

__all__ = ["FrameSet", "PSFSignal", "read_set", "frame_black", "measure_psf", "psf_signal", "psf_frame_problems",
           "wall_frame_problems", "MIN_KERNEL_SNR", "MIN_PEAK_SNR", "MAX_NOISE_FLOOR", "SATURATION"]

MIN_KERNEL_SNR = 100.0
MIN_PEAK_SNR = 20.0
MAX_NOISE_FLOOR = 0.01
SATURATION = 0.98  # a frame whose brightest pixel reaches this fraction of the file's full scale is clipped
_MIN_BACKGROUND = 100  # pixels outside the window needed to measure one frame's noise from its background


@dataclass
class FrameSet:
    """Frames averaged: ``mean`` (DN), ``var`` (one frame's variance per pixel, None for one frame), ``n``,
    ``first`` (the first file read)."""

    mean: np.ndarray
    var: np.ndarray | None
    n: int
    first: Path


def _shape(a: np.ndarray) -> str:
    return f"{a.shape[1]}×{a.shape[0]} px" + (" × 3 channels" if a.ndim == 3 else "")


def read_set(paths, pixel_format: str, problems: list, saturated_fix: str | None = None,
             white_level: float | None = None) -> FrameSet | None:
    """Read every file of ``paths``, noting in ``problems`` each unreadable one, each of another size than the
    first and (``saturated_fix``: the fix to name) each saturated one, against ``white_level`` (DN; None: the
    file's full scale); the readable frames of the first's size averaged (None when none is)."""
    total = sq = first = None
    n = 0
    for p in paths:
        try:
            f = read_frame(p, pixel_format)
        except DoefabError as exc:
            problems.append(str(exc))
            continue
        if first is None:
            first, total, sq = p, np.zeros_like(f), np.zeros_like(f)
        elif f.shape != total.shape:
            problems.append(f"{p} is {_shape(f)} but {first} is {_shape(total)}: every frame of a recording must "
                            f"have the same size and channels (re-record it or remove it from the list)")
            continue
        top = None
        if saturated_fix:
            try:
                top = (stated_white_level(p, pixel_format, "the recordings file's white_level")
                       if white_level is None else white_level)
            except DoefabError as exc:  # no clip level known: saturation cannot be checked (said once a set)
                problems.append(str(exc))
                saturated_fix = None
        clipped = raw_saturated(p, SATURATION, pixel_format, top) if top is not None else None
        if clipped is not None and clipped.any():  # a raw: its photosites, before the 2×2 binning averages them
            what = "the raw's white level" if white_level is None else "white_level"
            problems.append(f"{p}: {int(clipped.sum())} of its binned pixels hold a photosite at {SATURATION:.0%} "
                            f"or more of {what} ({top:.6g} DN), so the peak is clipped (binned 2×2 "
                            f"with its neighbours it reads lower): {saturated_fix} (keep every photosite below "
                            f"{SATURATION:.0%} of it)")
        elif top is not None and clipped is None:  # other files: their pixels are the sensor's
            peak, what = float(f.max(initial=0.0)), "the file's full scale" if white_level is None else "white_level"
            if peak >= SATURATION * top:
                problems.append(f"{p}: its brightest pixel, {peak:.6g} DN, is {peak / top:.1%} of {what} "
                                f"({top:.6g} DN), so the peak is clipped: {saturated_fix} (keep the peak "
                                f"below {SATURATION:.0%} of it)")
        total += f
        sq += f * f
        n += 1
    if n == 0:
        return None
    mean = total / n
    var = np.maximum(sq - n * mean * mean, 0.0) / (n - 1) if n > 1 else None
    return FrameSet(mean, var, n, first)


@dataclass
class PSFSignal:
    """A PSF recording's light: ``signal`` (mean frame less the darks', DN), ``frames``, ``peak`` (row, column),
    ``window`` (row and column slices of the kernel window), per channel (one entry for monochrome frames) the
    window's ``total`` (DN), ``kernel_snr`` and ``peak_snr``, how the ``noise`` was measured, and per channel the
    ``noise_floor``: the light that setting the window's negative pixels to zero would add, over its total
    (module docstring)."""

    signal: np.ndarray
    frames: int
    peak: tuple
    window: tuple
    total: tuple
    kernel_snr: tuple
    peak_snr: tuple
    noise: str
    noise_floor: tuple = ()


def _noise(frames: FrameSet, dark: FrameSet | None, s: np.ndarray, window) -> tuple[np.ndarray, str]:
    """Per-pixel variance of ``s`` (the dark-subtracted mean frame) and how it was measured."""
    if frames.n >= 2:
        var, how = frames.var / frames.n, f"frame-to-frame scatter of {frames.n} frames"
    else:
        outside = np.ones(s.shape[:2], bool)
        outside[window] = False
        if outside.sum() >= _MIN_BACKGROUND:
            bg = s[outside]  # (pixels,) or (pixels, 3)
            mad = np.median(np.abs(bg - np.median(bg, axis=0)), axis=0)
            var, how = np.broadcast_to((1.4826 * mad) ** 2, s.shape).copy(), "one frame's background scatter"
        elif dark is not None and dark.var is not None:
            var, how = dark.var.copy(), "the dark frames' scatter (one frame: no shot noise)"
        else:
            raise DoefabError("one frame, no background outside the kernel window and fewer than 2 dark frames: the "
                              "noise cannot be measured; record at least 2 frames")
    if dark is not None and dark.var is not None:
        var += dark.var / dark.n
    return var, how


def frame_black(black_level: float, paths, pixel_format: str):
    """The level (DN) subtracted from frames that have no dark frames: the recordings file's ``black_level`` where
    it gives one (> 0), else the level a raw file states for each of R, G, B (:func:`raw_black_level` of the
    first of ``paths``: the channels' pedestals differ, e.g. 2046/2048/2051 DN), else 0.

    Example: ``frame_black(0.0, ["psf/f_0.dng"], "auto")`` → ``array([512., 512., 512.])`` for a camera whose raw
    states 512 DN."""
    if black_level > 0 or not paths:
        return float(black_level)
    try:
        level = raw_black_level(paths[0], pixel_format)
    except DoefabError:
        return 0.0  # unreadable: the frame checks name it
    return level if level.any() else 0.0


def measure_psf(frames: FrameSet, dark: FrameSet | None, black_level, kernel: int) -> PSFSignal:
    """The light of a PSF recording in the ``kernel``-pixel window around its peak, and its signal-to-noise."""
    from scipy.ndimage import uniform_filter

    s = frames.mean - (dark.mean if dark is not None else black_level)
    mono = s if s.ndim == 2 else s.sum(axis=-1)
    peak = np.unravel_index(int(np.argmax(uniform_filter(mono, 3, mode="constant"))), mono.shape)
    (h, w), k = mono.shape, int(kernel)
    r0, c0 = (int(np.clip(c - k // 2, 0, max(n - k, 0))) for c, n in zip(peak, (h, w)))
    window = (slice(r0, r0 + k), slice(c0, c0 + k))
    var, how = _noise(frames, dark, s, window)
    chans = [(s, var)] if s.ndim == 2 else [(s[..., c], var[..., c]) for c in range(3)]
    total, ksnr, psnr, floor = [], [], [], []
    for sc, vc in chans:
        win, vwin = sc[window], vc[window]
        total.append(float(win.sum()))
        ksnr.append(_snr(total[-1], float(vwin.sum())))
        # the typical pixel's noise; where most pixels scatter by less than a DN (median 0), the window's mean
        noise_var = float(np.median(vwin)) or float(vwin.mean())
        psnr.append(_snr(float(win.max()), noise_var))
        floor.append(float(np.maximum(-win, 0.0).sum()) / total[-1] if total[-1] > 0 else math.inf)
    return PSFSignal(s, frames.n, (int(peak[0]), int(peak[1])), window, tuple(total), tuple(ksnr), tuple(psnr), how,
                     tuple(floor))


def _snr(signal: float, variance: float) -> float:
    """``signal`` over the noise σ; with no measurable noise, infinite for light and 0 for none."""
    if variance > 0:
        return signal / math.sqrt(variance)
    return math.inf if signal > 0 else 0.0


def psf_signal(rec, r, kernel: int) -> PSFSignal:
    """:func:`measure_psf` of the ``Recordings`` ``rec``'s PSF recording ``r`` (its frames and darks read; the first
    problem raised)."""
    problems: list[str] = []
    frames = read_set(r.frames, rec.pixel_format, problems)
    dark = read_set(r.dark, rec.pixel_format, problems) if r.dark else None
    if problems:
        raise DoefabError(problems[0])
    return measure_psf(frames, dark, frame_black(rec.black_level, r.frames, rec.pixel_format), kernel)


def _light_problems(r, frames: FrameSet, got: PSFSignal, kernel: int) -> list[str]:
    out = []
    names = [""] if len(got.total) == 1 else [" (red)", " (green)", " (blue)"]
    for name, total, ksnr, psnr, floor in zip(names, got.total, got.kernel_snr, got.peak_snr, got.noise_floor):
        if ksnr >= MIN_KERNEL_SNR and psnr >= MIN_PEAK_SNR and floor <= MAX_NOISE_FLOOR:
            continue
        dim = max(MIN_KERNEL_SNR / max(ksnr, 1e-9), MIN_PEAK_SNR / max(psnr, 1e-9))
        short = max(dim, max(floor, 0.0) / MAX_NOISE_FLOOR)  # the floor falls as 1/√frames, as the SNRs rise
        more = (f"or average more frames (about {math.ceil(frames.n * short ** 2)} at this exposure)" if dim < 30
                else "(the frames hold no PSF above the noise: check that the source is on and in the field of view, "
                     "and that the dark frames are of the same settings)")
        out.append(f"{frames.first} ({r.name}, {frames.n} frame{'s' * (frames.n > 1)}){name}: too few photons for "
                   f"the {kernel}×{kernel}-px kernel: the window's signal is {total:.4g} DN at a signal-to-noise "
                   f"ratio of {ksnr:.3g} (peak {psnr:.3g}; noise from {got.noise})"
                   + (f" and its noise, set to zero where negative, would add {floor:.2%} of false light"
                      if math.isfinite(floor) else "") + f"; the calibration needs ≥ {MIN_KERNEL_SNR:g} "
                   f"(peak ≥ {MIN_PEAK_SNR:g}) and ≤ {MAX_NOISE_FLOOR:.0%}: record more light (a longer exposure or a "
                   f"brighter source, up to the saturation limit) {more}")
    return out


BORDER_PX = 3  # the frame's outer rows and columns whose median is the background far from the spot


def _background_problem(r, frames: FrameSet, dark: FrameSet | None, black_level) -> str | None:
    """Each channel's frame border, far from the spot, once the darks (or black level) are subtracted, should read
    zero within its noise; an offset there (a black level left in, darks of other settings, or too much
    subtracted) adds to or takes from every pixel of the kernel window. Refused where a channel's border median
    lies more than 5 noise σ (the border's own scatter, from its MAD) and 0.1 % of its peak from zero, either way
    (channel by channel: offsets of opposite sign would cancel in their mean)."""
    s = frames.mean - (dark.mean if dark is not None else black_level)
    chans = [("", s)] if s.ndim == 2 else [(f" ({n})", s[..., c]) for c, n in enumerate(("red", "green", "blue"))]
    b = BORDER_PX
    for name, mono in chans:
        border = np.concatenate([mono[:b].ravel(), mono[-b:].ravel(), mono[b:-b, :b].ravel(),
                                 mono[b:-b, -b:].ravel()])
        level = float(np.median(border))
        sigma = 1.4826 * float(np.median(np.abs(border - level)))
        peak = float(mono.max())
        if abs(level) <= 5 * sigma or abs(level) <= 1e-3 * abs(peak):
            continue
        black = np.atleast_1d(np.asarray(black_level, np.float64))
        what = ("its dark frames are" if dark is not None else
                f"the black level ({'/'.join(f'{v:g}' for v in black)} DN) is")
        side = "above" if level > 0 else "below"
        read = "read as light" if level > 0 else "taken from the light"
        return (f"{frames.first} ({r.name}){name}: the frame's border, far from the spot, reads {abs(level):.4g} DN "
                f"{side} zero once {what} subtracted ({abs(level) / max(sigma, 1e-12):.3g} times its noise, "
                f"{abs(level) / max(abs(peak), 1e-300):.2%} of the peak): an offset that would be {read} in the "
                f"whole kernel window: give dark frames recorded with the source off at the frames' exposure and "
                f"gain, or the sensor's black_level")
    return None


def psf_frame_problems(rec, r, kernel: int) -> list[str]:
    """Every problem of the ``Recordings`` ``rec``'s PSF recording ``r``, each naming the file and the fix."""
    out: list[str] = []
    frames = read_set(r.frames, rec.pixel_format, out, "reduce the exposure or the source power", rec.white_level)
    dark = read_set(r.dark, rec.pixel_format, out) if r.dark else None
    if frames is None:
        return out
    m = frames.mean
    if dark is not None and dark.mean.shape != m.shape:
        raws = [frame_format(p, rec.pixel_format) == "raw" for p in (frames.first, dark.first)]
        binned = (" (a raw frame is binned 2×2 to R, G, B at half its size: give the darks as raw files of the same "
                  "camera too)" if raws[0] != raws[1] else "")
        out.append(f"{dark.first} is {_shape(dark.mean)} but {r.name}'s frames ({frames.first}) are {_shape(m)}: "
                   f"record the dark frames at the frames' size and settings{binned}")
    if r.wavelength_m is not None and m.ndim == 3:
        out.append(f"{frames.first}: {r.name} is a narrow-band recording (wavelength_nm) but its frames are colour "
                   f"({_shape(m)}): give monochrome frames (a monochrome camera, or one channel saved as TIFF), or "
                   f"write channels = \"rgb\" for a broadband source")
    if r.channels == "rgb" and m.ndim == 2:
        out.append(f"{frames.first}: {r.name} has channels = \"rgb\" but its frames are monochrome ({_shape(m)}): "
                   f"give colour (H, W, 3) frames (a raw file is binned to R, G, B), or write wavelength_nm for a "
                   f"narrow-band source")
    if min(m.shape[:2]) < kernel:
        out.append(f"{frames.first}: {r.name}'s frames are {_shape(m)}, smaller than the design's "
                   f"{kernel}×{kernel}-px kernel: record a window of at least {kernel}×{kernel} px around the PSF (2K × 2K leaves room "
                   f"for the source's offset)")
    if out:
        return out
    black = frame_black(rec.black_level, r.frames, rec.pixel_format)
    zero = float(np.mean(dark.mean)) if dark is not None else float(np.mean(black))
    if zero >= float(np.mean(m)):  # a point source adds light: a frame no brighter than its zero is another's
        what = (f"its dark frames' mean ({dark.first})" if dark is not None else
                "black_level" if rec.black_level > 0 else "the raw's own black level")
        return [f"{frames.first} ({r.name}): {what}, {zero:.4g} DN, is no darker than the frames' mean, "
                f"{float(np.mean(m)):.4g} DN: record the darks at the frames' exposure, gain and bit depth (a "
                f"16-bit dark under 8-bit frames reads 256 times too bright), or give the sensor's black_level"]
    floor = _background_problem(r, frames, dark, black)
    if floor:
        return [floor]
    try:
        return _light_problems(r, frames, measure_psf(frames, dark, black, kernel), kernel)
    except DoefabError as exc:
        return [f"{frames.first} ({r.name}): {exc}"]


def wall_frame_problems(rec, w) -> list[str]:
    """Every problem of the ``Recordings`` ``rec``'s white-wall recording ``w``, each naming the file and the fix."""
    out: list[str] = []
    fix = "reduce the exposure or the wall's illumination"
    coded = read_set(w.coded_view, rec.pixel_format, out, fix, rec.white_level)
    plain = read_set(w.plain_view, rec.pixel_format, out, fix, rec.white_level)
    dark = read_set(w.dark, rec.pixel_format, out) if w.dark else None
    if coded is not None and plain is not None and coded.mean.shape != plain.mean.shape:
        out.append(f"{plain.first} (plain view) is {_shape(plain.mean)} but {coded.first} (coded view) is "
                   f"{_shape(coded.mean)}: {w.name}'s two views must be of one capture (same size and channels)")
    ref = coded or plain
    if dark is not None and ref is not None and dark.mean.shape != ref.mean.shape:
        out.append(f"{dark.first} is {_shape(dark.mean)} but {w.name}'s views ({ref.first}) are {_shape(ref.mean)}: "
                   f"record the dark frames at the views' size and settings")
    return out
