"""Camera raw files through LibRaw (rawpy): one read gives a frame's Bayer mosaic binned 2×2 to R, G, B, the
brightest photosite of each colour per cell, and the file's black and white levels (``doefab.lab.frames`` reads
frames of every format with it).
"""

from __future__ import annotations

import contextlib
import functools
import os
import tempfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from doefab.errors import DoefabError

__all__ = ["RawData", "raw_data", "bin_bayer"]


def bin_bayer(mosaic: np.ndarray, pattern: str | np.ndarray) -> np.ndarray:
    """A Bayer mosaic (H, W) binned 2×2 to (H//2, W//2, 3): R, G (the mean of the two greens), B.

    ``pattern`` is the colour of each pixel of the top-left 2×2 cell, row by row (``"RGGB"``, ``"BGGR"``,
    ``"GRBG"``, ``"GBRG"``, or a 2×2 array of those letters); an odd last row or column is dropped."""
    cell = np.asarray(list(pattern) if isinstance(pattern, str) else pattern).reshape(-1)
    letters = "".join(str(c).upper() for c in cell)
    if len(letters) != 4 or sorted(letters) != ["B", "G", "G", "R"]:
        raise DoefabError(f"Bayer pattern {letters!r} is not a 2×2 cell of one R, two G and one B: use e.g. "
                          f"'RGGB', 'BGGR', 'GRBG' or 'GBRG'")
    m = np.asarray(mosaic, dtype=np.float64)
    if m.ndim != 2 or m.shape[0] < 2 or m.shape[1] < 2:
        raise DoefabError(f"a Bayer mosaic must be a 2-D array of at least 2×2 pixels, got shape {m.shape}")
    h, w = (m.shape[0] // 2) * 2, (m.shape[1] // 2) * 2
    sub = [m[i:h:2, j:w:2] for i in (0, 1) for j in (0, 1)]  # the cell's four pixels, row by row
    greens = [s for s, c in zip(sub, letters) if c == "G"]
    return np.stack([sub[letters.index("R")], 0.5 * (greens[0] + greens[1]), sub[letters.index("B")]], axis=-1)


class RawData(NamedTuple):
    """What one read of a raw file gives: ``binned`` (H/2, W/2, 3) R, G, B DN (:func:`bin_bayer`); ``peak`` the same
    shape, the brightest photosite of that colour in each 2×2 cell; ``black`` R, G, B black levels (DN, binned as
    the mosaic is); ``white`` the white level (DN)."""

    binned: np.ndarray
    peak: np.ndarray
    black: np.ndarray
    white: float


def raw_data(path: Path) -> RawData:
    """:class:`RawData` of ``path``, read once for a few calls in a row (a frame's pixels, levels and clipped
    photosites are asked for one after another): cached by path, inode, size, modification and change time (a
    rewrite that keeps the size and sets the old modification time back still changes the change time)."""
    try:
        st = path.stat()
    except OSError as exc:
        raise DoefabError(f"{path} cannot be read ({exc.strerror or exc}): check the path") from None
    return _raw_cached(str(path), st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


@functools.lru_cache(maxsize=2)
def _raw_cached(name: str, inode: int, size: int, mtime_ns: int, ctime_ns: int) -> RawData:
    path = Path(name)
    with _libraw(path) as raw:
        letters = _raw_pattern(raw, path)
        mosaic = np.array(raw.raw_image_visible)  # a copy: LibRaw frees its buffer when the file closes
        per = np.asarray(raw.black_level_per_channel, dtype=np.float64)
        colors = np.array(raw.raw_colors_visible[:2, :2]).reshape(-1)
        white = float(raw.white_level)
    black = bin_bayer(np.array([per[int(c)] for c in colors]).reshape(2, 2), letters).reshape(3)
    binned = bin_bayer(mosaic, letters).astype(np.float32)  # exact: integers and their halves below 2^24
    h, w = binned.shape[:2]
    cell = [mosaic[i:2 * h:2, j:2 * w:2] for i in (0, 1) for j in (0, 1)]  # the cell's four sites, row by row
    peak = np.stack([np.maximum.reduce([x for x, c in zip(cell, letters) if c == colour]) for colour in "RGB"],
                    axis=-1)
    for arr in (binned, peak, black):
        arr.setflags(write=False)  # shared by the cache's callers
    return RawData(binned, peak, black, white)


@contextlib.contextmanager
def _libraw(path: Path):
    """``path`` opened with LibRaw and its data unpacked, LibRaw's messages on the C library's stderr kept out of
    the terminal (a damaged file gets one error, ours, which quotes them); an error naming the file and the fix
    when it cannot be read. Only the opening and unpacking are LibRaw's to fail: what the block does is its own."""
    import rawpy

    with tempfile.TemporaryFile() as said:
        raw = None
        try:
            with _stderr_to(said):
                raw = rawpy.imread(str(path))
                if raw.raw_type == rawpy.RawType.Flat:
                    _ = raw.raw_image_visible  # unpacks the data: a truncated file fails here
        except Exception as exc:  # LibRaw's errors have several types, their texts bytes
            if raw is not None:
                raw.close()
            said.seek(0)
            note = " ".join(said.read().decode("utf-8", "replace").split())
            text = exc.args[0].decode("utf-8", "replace") if exc.args and isinstance(exc.args[0], bytes) else str(exc)
            raise DoefabError(f"{path} cannot be read as raw (LibRaw: {text}{'; ' + note if note else ''}): check "
                              f"that the file is a complete camera raw (a copy that ended early reads so), or set "
                              f"pixel_format to the format it is in") from None
    with raw:
        yield raw


@contextlib.contextmanager
def _stderr_to(fh):
    """File descriptor 2 sent to ``fh`` for the block (LibRaw writes there from C)."""
    import sys

    try:
        if sys.stderr is not None:
            sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no stderr descriptor (an embedded interpreter): nothing to keep
        yield
        return
    try:
        os.dup2(fh.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _raw_pattern(raw, path: Path) -> str:
    import rawpy

    if raw.raw_type != rawpy.RawType.Flat:
        raise DoefabError(f"{path} is a linear (demosaiced) raw, not a Bayer mosaic (e.g. a ProRAW or linear DNG, "
                          f"a scanner's raw): export its linear R, G, B as a 16-bit TIFF without white balance or "
                          f"tone curve and read that, the sensor pitch of the design's camera being the file's pixel")
    colors = np.asarray(raw.raw_colors_visible)
    desc = raw.color_desc.decode("ascii", "replace")
    block = colors[:6, :6]
    periodic = block.shape == (6, 6) and np.array_equal(block, np.tile(block[:2, :2], (3, 3)))
    letters = "".join(desc[int(c)] for c in block[:2, :2].reshape(-1)) if periodic else ""
    if sorted(letters) != ["B", "G", "G", "R"]:
        raise DoefabError(f"{path} is not a 2×2 Bayer (R, G, G, B) raw: its colour filter repeats over more than 2×2 "
                          f"pixels (e.g. X-Trans) or holds other colours: demosaic it to a linear 16-bit TIFF with "
                          f"no white balance, scaling or rotation (e.g. `dcraw -4 -T -o 0 -r 1 1 1 1 -t 0`) and read "
                          f"that; its pixels are then the photosites, not the 2×2 cells a Bayer raw is binned to, so "
                          f"the design's camera must have the photosite pitch")
    return letters


