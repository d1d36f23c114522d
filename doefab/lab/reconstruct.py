"""A camera's own captures reconstructed: read, scaled, unmixed with the calibrated crosstalk, then run through a
task's network in overlapping tiles, so that what the network computes at once does not grow with the image.

**Captures.** :func:`read_capture` reads a frame with :func:`doefab.lab.frames.read_frame` and scales it to
[0, 1]: ``(DN − black) / (white − black)``, ``white`` the file's full scale (:func:`doefab.lab.frames.full_scale`:
``2**bits − 1``, a raw's white level) unless given, ``black`` the raw's own black level (0 for other files) unless
given; values outside [0, 1] are clipped (noise below black, nothing above white), and a frame far below black
(a wrong black level) or a 16-bit file whose values stay within 14 bits (a 12- or 14-bit camera's numbers, its
scale unstated) is refused (:func:`read_capture`). The networks read colour
captures (3 channels) quantised to at least 8 bits. :func:`unmix_views` undoes the dual-pixel crosstalk with a
calibration's per-column ratios (``crosstalk.json``; the coded capture is the right view, the plain one the left,
:mod:`doefab.imaging.crosstalk`); a photodiode that saturated stays saturated, as in the camera model's pipeline.

**Tiles.** The networks take sides that are multiples of 32 (at least 64). The image is extended by edge
replication at the bottom and right to multiples of 32 (the whole-image network would need the same) and cut
into tiles of ``tile`` × ``tile`` pixels — an image narrower than that along an axis is one tile across — whose
starts are multiples of 32: consecutive tiles share ``overlap`` pixels (a multiple of 32, at most half a tile) and
the last tile of a row or column ends at the image's end. Each tile is reconstructed alone. A pixel near a tile's
edge lacks the light that the PSF brought from beyond it and the context the network would see, so the tiles are
blended with a raised-cosine window: along each shared edge the weight is 0 over the outer quarter of the
overlap, rises as ``sin²`` over its middle half and is 1 beyond; the two tiles' weights sum to 1 there, and every
result is divided by the sum of the weights. The default overlap is the PSF's kernel (the reach of its light)
rounded up to a multiple of 32. A network that reads a few pixels around each pixel gives, tiled, exactly its
whole-image result; the shipped networks see farther (the depth network's trunk, the HDR network's
least-squares solve, whose conjugate-gradient steps depend on the whole frame), so their tiled results differ from
the whole-image ones by a stated tolerance (``docs/guide/after-the-fab.md``).

The proposed hyperspectral network estimates the scene's light from the central 256² pixels of its input (one
light per scene); a tile would estimate its own. :func:`iter_tiled` estimates it once, from the centre of the
whole (extended) image as the whole-image network would, and every tile uses it.

Memory: the tile's working set (the network, its FFT canvases) does not grow with the image; the image's own
arrays do — the two captures (2 × 3 × 4 bytes per pixel), the result (4 bytes per channel per pixel) and a band of
one tile's height across the image (the blend) — ``benchmarks/reconstruct_memory.py`` measures both parts.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from doefab.applications import application, has
from doefab.errors import DoefabError

__all__ = ["MULTIPLE", "MIN_SIDE", "DEFAULT_TILE", "default_overlap", "check_tiling", "tile_starts", "blend_window",
           "iter_tiled", "reconstruct_tiled", "output_channels", "capture_levels", "read_capture", "unmix_views",
           "load_views"]

MULTIPLE = 32  # the networks' sides are multiples of this (``reconstruction.networks.check_input``) ...
MIN_SIDE = 64  # ... and at least this
DEFAULT_TILE = 512  # pixels: 0.5–1.3 GB of working set for the shipped networks (benchmarks/reconstruct_memory.py)
MIN_BITS = 8  # captures quantised more coarsely than this are refused


def _round_up(n: int, m: int = MULTIPLE) -> int:
    return -(-int(n) // m) * m


def default_overlap(rec, psf=None) -> int:
    """The overlap of consecutive tiles: the largest PSF kernel (the network's, ``psf``'s) rounded up to a
    multiple of 32 (a pixel's light comes from up to half a kernel away)."""
    k = max(int(rec.pair.coded.shape[-1]), int(psf.coded.shape[-1]) if getattr(psf, "coded", None) is not None else 0)
    return _round_up(k)


def _is_count(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def _too_wide(what: str, overlap: int, tile: int):
    half = tile // 2 // MULTIPLE * MULTIPLE
    raise DoefabError(f"{what} ({tile} px): give a tile of at least {2 * overlap} px "
                      f"(--tile {_round_up(2 * overlap)} --overlap {overlap}) or an overlap of at most {half} px "
                      f"(--overlap {half})")


def check_tiling(tile: int, overlap: int, shape: tuple[int, int], what: str = "the captures") -> None:
    """Refuse a tile or overlap the networks cannot take, or an image smaller than their smallest input, with
    values that work (``tile``, ``overlap``: the ``--tile`` and ``--overlap`` of ``doefab reconstruct``)."""
    rules = {"tile": (tile, MIN_SIDE), "overlap": (overlap, MULTIPLE)}  # value, least
    ok = {name: _is_count(v) and v >= lo and v % MULTIPLE == 0 for name, (v, lo) in rules.items()}
    for name, (v, lo) in rules.items():
        if not ok[name]:
            good = max(lo, _round_up(v)) if _is_count(v) else lo
            if name == "tile" and ok["overlap"]:  # a tile that also holds the overlap twice: its fix must pass both
                good = max(good, 2 * overlap)
            if name == "overlap" and 2 * good > tile:  # both rules in one message: its fix must pass
                _too_wide(f"overlap {v!r} must be a multiple of {MULTIPLE} pixels, and the next one, {good}, is "
                          f"more than half the tile", good, tile)
            raise DoefabError(f"{name} {v!r} must be a multiple of {MULTIPLE} pixels, at least {lo} (the networks' "
                              f"input sides are multiples of {MULTIPLE}): e.g. {name} {good} (--{name} {good})")
    if 2 * overlap > tile:
        _too_wide(f"overlap {overlap} px is more than half the tile", overlap, tile)
    h, w = shape
    if min(h, w) < MIN_SIDE:
        raise DoefabError(f"{what} are {w}×{h} px: the networks need at least {MIN_SIDE} px on each side: capture "
                          f"(or crop) at least {MIN_SIDE}×{MIN_SIDE} pixels")


def tile_starts(length: int, tile: int, overlap: int) -> list[int]:
    """Starts of the tiles along an axis of ``length`` pixels (already a multiple of 32): every ``tile −
    overlap`` pixels, the last one ending at the end; one tile when it spans the axis."""
    if tile >= length:
        return [0]
    step = tile - overlap
    starts = list(range(0, length - tile + 1, step))
    if starts[-1] + tile < length:
        starts.append(length - tile)
    return starts


def blend_window(tile: int, overlap: int, first: bool, last: bool) -> np.ndarray:
    """The 1-D blending weight over a tile: 0 over the outer quarter of the overlap on each shared side, ``sin²``
    up to 1 over its middle half, 1 in the core (a side at the image's edge (``first``/``last``) keeps 1)."""
    x = np.arange(tile) + 0.5
    guard = overlap / 4
    ramp = np.sin(0.5 * np.pi * np.clip((x - guard) / (overlap - 2 * guard), 0.0, 1.0)) ** 2
    w = np.ones(tile)
    if not first:
        w = w * ramp
    if not last:
        w = w * ramp[::-1]
    return w


def output_channels(rec) -> int:
    """Channels of the network's result: 3 (HDR radiance), one per band (spectra), 1 (depth in metres)."""
    return len(rec.pair.wavelengths) if has(rec.task, "spectral") else application(rec.task).out_channels


def _check_captures(coded, uncoded) -> tuple[int, int]:
    for name, x in (("coded", coded), ("uncoded", uncoded)):
        if not isinstance(x, np.ndarray) or x.ndim != 3 or x.shape[0] != 3 or x.dtype.kind != "f":
            raise DoefabError(f"{name} must be a [3, H, W] float array in [0, 1] (a colour capture scaled to the "
                              f"sensor's white level: read_capture), got "
                              f"{getattr(x, 'dtype', type(x).__name__)} {getattr(x, 'shape', '')}")
        lo, hi = float(x.min()), float(x.max())
        if not (math.isfinite(lo) and math.isfinite(hi)) or lo < 0 or hi > 1:
            raise DoefabError(f"{name} holds values {lo:.4g}–{hi:.4g}: captures are in [0, 1] (0 = black, 1 = the "
                              f"sensor's white level): scale and clip them first (read_capture does)")
    if coded.shape != uncoded.shape:
        raise DoefabError(f"coded {coded.shape[2]}×{coded.shape[1]} px and uncoded {uncoded.shape[2]}×"
                          f"{uncoded.shape[1]} px differ in size: give the two views of one exposure")
    return coded.shape[1], coded.shape[2]


def _tile(x: np.ndarray, r: int, c: int, rows: int, cols: int) -> np.ndarray:
    """``x[:, r:r+rows, c:c+cols]``, extended by edge replication where it runs past the image."""
    t = x[:, r:r + rows, c:c + cols]
    short = (rows - t.shape[1], cols - t.shape[2])
    return np.pad(t, ((0, 0), (0, short[0]), (0, short[1])), mode="edge") if any(short) else np.ascontiguousarray(t)


_LIGHT_SIDE = 256  # the proposed spectral network's light comes from the central 256² (illuminant.max_side)


@contextmanager
def _scene_light(rec, coded, uncoded, psf, padded: tuple[int, int], info: dict | None = None):
    """The proposed hyperspectral network's light, estimated once from the centre of the whole extended image
    (the pixels the whole-image network would use) and fixed for every tile (``SpectralNet.light``); ``info``
    given, its ``"light"`` becomes {library illuminant: weight} of the estimate (weights of at least 0.01)."""
    model = rec.model
    if not has(rec.task, "spectral") or rec.variant != "proposed" or getattr(model, "inverses", None) is None:
        yield
        return
    import torch

    from doefab.reconstruction.illuminant import mix_illuminants, search_illuminant

    (hp, wp), side = padded, _LIGHT_SIDE
    r0, c0 = max(0, (hp - side) // 2), max(0, (wp - side) // 2)
    crop = [torch.from_numpy(_tile(x, r0, c0, min(side, hp), min(side, wp)))[None].float() for x in (coded, uncoded)]
    args = (*crop, rec._psf(psf)[0].float().cpu(), model.response.cpu(), model.inverses.cpu())
    if model.mix:
        w = mix_illuminants(*args)
        w = w / w.sum(dim=1, keepdim=True).clamp_min(1e-12)
    else:
        w = torch.nn.functional.one_hot(search_illuminant(*args)[0], model.inverses.shape[0]).float()
    model.light = w.to(rec.device)
    if info is not None:
        from doefab.reconstruction.illuminant import illuminant_names

        info["light"] = {n: round(float(x), 3) for n, x in zip(illuminant_names(), w[0].tolist()) if x >= 0.01}
    try:
        yield
    finally:
        model.light = None


def iter_tiled(rec, coded: np.ndarray, uncoded: np.ndarray, tile: int = DEFAULT_TILE, overlap: int | None = None,
               psf=None, progress: bool = False, info: dict | None = None):
    """Yield ``(row, block)``: the result of rows ``row`` … ``row + len`` of the image, [C, rows, W] float32 (C:
    :func:`output_channels`), top to bottom, each as soon as no later tile reaches it (module docstring). The
    spectral network's light stays fixed until the generator is exhausted or closed.

    Args:
        rec: a ``doefab.reconstruction.loader.Reconstructor``.  coded, uncoded: [3, H, W] float captures in [0, 1].
        tile, overlap: pixels, multiples of 32 (overlap None: :func:`default_overlap`).  psf: a PSF pair the
            network is conditioned on instead of its own (a measured part's).  progress: a tqdm bar over tiles.
        info: a dict that receives what the reconstruction estimated of the scene: the proposed hyperspectral
            network's light (``"light"``: {library illuminant: weight}, from the image's central 256² px).
    """
    from tqdm.auto import tqdm

    h, w = _check_captures(coded, uncoded)
    overlap = default_overlap(rec, psf) if overlap is None else overlap
    check_tiling(tile, overlap, (h, w))
    rec._psf(psf)  # a PSF pair the network cannot take is refused before any tile
    hp, wp = _round_up(h), _round_up(w)
    th, tw = min(tile, hp), min(tile, wp)  # an image narrower than a tile is one tile across
    rows, cols = tile_starts(hp, th, overlap), tile_starts(wp, tw, overlap)
    ch = output_channels(rec)
    col_w = [blend_window(tw, overlap, i == 0, i == len(cols) - 1).astype(np.float32) for i in range(len(cols))]
    acc = np.zeros((ch, th, wp), np.float32)  # the band of rows [row, row + th): weighted sums ...
    wsum = np.zeros((th, wp), np.float32)  # ... and their weights
    with _scene_light(rec, coded, uncoded, psf, (hp, wp), info), \
            tqdm(total=len(rows) * len(cols), desc=f"{rec.task} tiles", unit="tile", disable=not progress) as bar:
        for i, r in enumerate(rows):
            row_w = blend_window(th, overlap, i == 0, i == len(rows) - 1).astype(np.float32)
            for c, cw in zip(cols, col_w):
                y = rec(_tile(coded, r, c, th, tw), _tile(uncoded, r, c, th, tw), psf=psf)
                wt = row_w[:, None] * cw[None, :]
                acc[:, :, c:c + tw] += y.reshape(ch, th, tw) * wt
                wsum[:, c:c + tw] += wt
                bar.update()
            done = (rows[i + 1] if i + 1 < len(rows) else hp) - r  # rows no later tile reaches
            n = min(done, h - r)
            yield r, acc[:, :n, :w] / wsum[:n, :w]
            acc[:, :th - done], acc[:, th - done:] = acc[:, done:].copy(), 0.0
            wsum[:th - done], wsum[th - done:] = wsum[done:].copy(), 0.0


def reconstruct_tiled(rec, coded: np.ndarray, uncoded: np.ndarray, tile: int = DEFAULT_TILE,
                      overlap: int | None = None, psf=None, progress: bool = False) -> np.ndarray:
    """The network's result for a whole capture pair, reconstructed in blended tiles (:func:`iter_tiled`):
    [3, H, W] HDR radiance (1 = the clipping level) | [C, H, W] spectra | [H, W] depth in metres, float32."""
    h, w = _check_captures(coded, uncoded)
    out = np.empty((output_channels(rec), h, w), np.float32)
    for r, block in iter_tiled(rec, coded, uncoded, tile, overlap, psf, progress):
        out[:, r:r + block.shape[1]] = block
    return out[0] if has(rec.task, "depth") else out


MOST_ABOVE_WHITE = 0.01  # the share of a frame's values that may lie above --white-level (clipped to it)


def capture_levels(path, black_level: float | None = None, white_level: float | None = None,
                   pixel_format: str = "auto") -> tuple[np.ndarray, float]:
    """(black [R, G, B], white) in DN that :func:`read_capture` scales ``path`` by: ``black_level`` for every
    channel where given, else the raw's own level per channel (its channels' pedestals differ; 0 for other files);
    ``white_level`` where given, else the file's stated white level; an error naming the fix when the file states
    none or black is not below white.

    Example: ``capture_levels("coded.dng")`` → ``(array([512., 512., 512.]), 65535.0)``."""
    from doefab.lab.frames import raw_black_level, stated_white_level

    white = (stated_white_level(path, pixel_format, "--white-level") if white_level is None
             else float(white_level))
    black = (np.asarray(raw_black_level(path, pixel_format), np.float64) if black_level is None
             else np.full(3, float(black_level)))
    if not (white > float(black.max()) and float(black.min()) >= 0):
        raise DoefabError(f"{path}: black level {'/'.join(f'{b:g}' for b in black)} DN must be ≥ 0 and below the "
                          f"white level {white:g} DN: give --black-level of the dark frames' mean (e.g. 0, or 2048 "
                          f"for many 14-bit raws)")
    return black, white


FAR_BELOW_BLACK = 0.05  # a value this share of the range below black is no noise about it: a wrong black level


def _check_scale(path, dn, black, white: float, white_level) -> None:
    """Refuse a 16-bit file whose values stay within 14 bits (a 12- or 14-bit camera's numbers, unscaled, read 16×
    or 4× too dark and clip nowhere) unless ``--white-level`` says its scale, and a frame of which more than
    ``MOST_ABOVE_WHITE`` lies far below black (``FAR_BELOW_BLACK``)."""
    top = float(np.max(dn))
    if white_level is None and white == 2**16 - 1 and 0 < top <= 2**14 - 1:  # (a frame of zeros has no scale)
        raise DoefabError(f"{path}: its values stay within 14 bits (largest {top:g} DN of the 16-bit file's 65535): "
                          f"a 12- or 14-bit camera's numbers in a 16-bit file read 16× or 4× too dark and clip "
                          f"nowhere: give --white-level, the camera's white level (4095 for 12-bit data, 16383 for "
                          f"14-bit; 65535 where the frame is 16-bit and this dark)")
    low = float(np.mean(dn < float(np.min(black)) - FAR_BELOW_BLACK * (white - float(np.max(black)))))
    if low > MOST_ABOVE_WHITE:
        raise DoefabError(f"{path}: {low:.1%} of its values lie more than {FAR_BELOW_BLACK:.0%} of the range below "
                          f"the black level {float(np.min(black)):g} (down to {float(np.min(dn)):g}): no sensor noise "
                          f"reaches that far; give --black-level of the dark frames' mean (for a float file already "
                          f"black-subtracted, 0)")


def read_capture(path, black_level: float | None = None, white_level: float | None = None,
                 pixel_format: str = "auto") -> np.ndarray:
    """One view of a capture as a [3, H, W] float32 array in [0, 1] (module docstring); refuses, naming the file
    and the fix, a frame that is not colour, one of fewer than 8 bits and one with no known white level. A raw
    frame's binned pixel that holds a photosite at 98 % of its white level or more reads 1 (clipped) in that
    channel: binned with an unclipped photosite it would read below the clip level.

    ``black_level``, ``white_level``: digital numbers (None: :func:`capture_levels`)."""
    from doefab.lab.frames import raw_saturated, read_frame
    from doefab.reconstruction.highlights import CLIPPED

    path = Path(path)
    dn = read_frame(path, pixel_format)
    if dn.ndim != 3:
        raise DoefabError(f"{path} is a monochrome frame ({dn.shape[1]}×{dn.shape[0]} px): the networks read colour "
                          f"captures (R, G, B): give the camera's colour frames (a 16-bit RGB TIFF, or the raw/DNG, "
                          f"which is binned to R, G, B)")
    black, white = capture_levels(path, black_level, white_level, pixel_format)
    if white_level is None and 1 < white < 2**MIN_BITS - 1:  # (1.0: a float file, normalised)
        raise DoefabError(f"{path} holds {math.log2(white + 1):.0f}-bit values (full scale {white:g}): the networks "
                          f"need captures of at least {MIN_BITS} bits: save the camera's frames as 16-bit TIFFs or "
                          f"give the raw/DNG")
    _check_scale(path, dn, black, white, white_level)
    above = float(np.mean(dn > white * (1 + 1e-6))) if white_level is not None else 0.0
    if above > MOST_ABOVE_WHITE:  # a clip level (or a linearity limit below it) that much of the frame exceeds
        raise DoefabError(f"{path}: {above:.1%} of its values lie above --white-level {white:g} DN (up to "
                          f"{float(np.max(dn)):g} DN): the level at which the sensor clips, or a linearity limit "
                          f"below it, leaves at most {MOST_ABOVE_WHITE:.0%} of a frame above it: give the sensor's "
                          f"white level (the file's full scale when it holds the camera's numbers unscaled), or "
                          f"leave --white-level out")
    clipped = raw_saturated(path, CLIPPED, pixel_format, white)
    out = np.empty((3, *dn.shape[:2]), np.float32)
    for k in range(3):  # channel by channel: no full-size float64 temporary beyond the frame itself
        out[k] = np.clip((dn[..., k] - black[k]) / (white - black[k]), 0.0, 1.0)
        if clipped is not None:
            out[k][clipped[..., k]] = 1.0
    return out


def unmix_views(coded: np.ndarray, uncoded: np.ndarray, crosstalk, where: str = "the captures",
                rows: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """``(coded, uncoded)`` with the dual-pixel crosstalk undone by ``crosstalk`` (a ``DualPixelCrosstalk`` whose
    ``estimate`` holds the calibrated per-column ratios, e.g. ``DualPixelCrosstalk.load(crosstalk.json)``), in
    place, ``rows`` rows at a time; a saturated view stays saturated (1), the rest clipped to [0, 1]."""
    from doefab.imaging.crosstalk import unmix_crosstalk

    a, b = (np.asarray(x, np.float64) for x in (crosstalk.estimate or (None, None)))
    if crosstalk.estimate is None or a.ndim > 1 or b.ndim > 1:
        raise DoefabError("crosstalk must be a calibrated camera with per-column ratios (DualPixelCrosstalk.load of "
                          "the crosstalk.json that doefab calibrate wrote)")
    w = coded.shape[-1]
    if a.size not in (1, w):
        raise DoefabError(f"the crosstalk calibration holds {a.size} columns but {where} are {w} px wide: the "
                          f"ratios are per sensor column, so calibrate with white-wall frames of the captures' size "
                          f"and format (doefab calibrate), or give captures {a.size} px wide")
    for r in range(0, coded.shape[-2], rows):
        c, u = coded[:, r:r + rows], uncoded[:, r:r + rows]
        sat_c, sat_u = c >= 1.0, u >= 1.0
        left, right = unmix_crosstalk(u, c, a, b)  # the plain half's light is the left view, the coded the right
        c[...] = np.where(sat_c, 1.0, np.clip(right, 0.0, 1.0))
        u[...] = np.where(sat_u, 1.0, np.clip(left, 0.0, 1.0))
    return coded, uncoded


def load_views(coded_path, uncoded_path, crosstalk=None, black_level: float | None = None,
               white_level: float | None = None, pixel_format: str = "auto", tile: int | None = None,
               overlap: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The two views of one exposure, read (:func:`read_capture`), checked to be of one size (and, ``tile``
    given, one that the tiling takes: :func:`check_tiling`), and unmixed (:func:`unmix_views`) when
    ``crosstalk`` is given: ``(coded, uncoded)`` [3, H, W]."""
    if black_level is None:  # one exposure: both views on one pedestal
        b_c, b_u = (capture_levels(p, None, white_level, pixel_format)[0] for p in (coded_path, uncoded_path))
        if not np.allclose(b_c, b_u):
            raise DoefabError(f"{coded_path} and {uncoded_path} state different black levels "
                              f"({'/'.join(f'{b:g}' for b in b_c)} and {'/'.join(f'{b:g}' for b in b_u)} DN): the two "
                              f"views of one exposure share the sensor's: give them in one format, or --black-level")
    coded = read_capture(coded_path, black_level, white_level, pixel_format)
    uncoded = read_capture(uncoded_path, black_level, white_level, pixel_format)
    if coded.shape != uncoded.shape:
        raise DoefabError(f"{coded_path} is {coded.shape[2]}×{coded.shape[1]} px but {uncoded_path} is "
                          f"{uncoded.shape[2]}×{uncoded.shape[1]} px: pair the two views of one exposure (the files "
                          f"are paired in sorted order)")
    if tile is not None:
        check_tiling(tile, overlap, coded.shape[1:], f"{coded_path} and {uncoded_path}")
    if crosstalk is not None:
        unmix_views(coded, uncoded, crosstalk, f"{coded_path} and {uncoded_path}")
    return coded, uncoded
