"""Camera frames as a lab has them: NumPy arrays, 8/16-bit PNG, 8/16/32-bit and float TIFF, raw/DNG.

Every reader returns float64 digital numbers (DN) as stored, shape (H, W) or (H, W, 3); nothing is subtracted or
scaled (black level and darks are the recordings' business, ``doefab.lab.recordings``). A raw file goes through
LibRaw (rawpy): its visible Bayer mosaic binned 2×2 into R, G (mean of the two greens) and B at half resolution
(:func:`bin_bayer`); its white level is :func:`full_scale` and its black level per channel :func:`raw_black_level`.

- ``pixel_format`` ``"auto"`` picks by extension: ``.npy``; ``.png``; ``.tif``/``.tiff``; a camera raw
  (``.dng``, ``.nef``, ``.cr2``, ``.cr3``, ``.arw``, ``.raf``, ``.orf``, ``.rw2``, ``.pef``, ``.srw``, ``.raw`` …).
- A 16-bit *colour* PNG is refused: Pillow, which reads PNGs, keeps only 8 of its bits (save it as a TIFF).
- :func:`full_scale` is the largest DN the file can hold: ``2**bits - 1`` of an integer file (a TIFF's
  BitsPerSample, so a 12-bit TIFF gives 4095), the raw's white level; a float file is taken as normalised
  (1.0) when its values are ≤ 1, else no clipping level is known (``inf``). :func:`stated_white_level` is the
  sensor's clip level a file states: its full scale, refused (naming the setting that gives it) for floats above 1
  and integers wider than 16 bits.
"""

from __future__ import annotations

import glob
import io
import math
import os
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.io import atomic_write_bytes
from doefab.lab.rawframes import bin_bayer, raw_data

__all__ = ["PIXEL_FORMATS", "RAW_EXTENSIONS", "frame_format", "expand", "read_frame", "full_scale",
           "stated_white_level", "raw_black_level", "raw_saturated", "bin_bayer", "mean_frames", "write_frame"]

PIXEL_FORMATS = ("auto", "npy", "png", "tiff", "raw")
RAW_EXTENSIONS = (".dng", ".nef", ".nrw", ".cr2", ".cr3", ".crw", ".arw", ".srf", ".sr2", ".raf", ".orf", ".rw2",
                  ".pef", ".srw", ".x3f", ".3fr", ".iiq", ".mos", ".erf", ".kdc", ".mrw", ".raw", ".rwl")
SENSOR_BITS = 16  # no camera's digital numbers are wider: a wider integer file's full scale is not its clip level
_BY_EXT = {".npy": "npy", ".png": "png", ".tif": "tiff", ".tiff": "tiff", **{e: "raw" for e in RAW_EXTENSIONS}}


def frame_format(path: str | Path, pixel_format: str = "auto") -> str:
    """The reader for ``path``: ``pixel_format`` itself, or under ``"auto"`` the one its extension names."""
    if pixel_format not in PIXEL_FORMATS:
        raise DoefabError(f"pixel_format {pixel_format!r} is not known: use one of {', '.join(PIXEL_FORMATS)}")
    if pixel_format != "auto":
        return pixel_format
    fmt = _BY_EXT.get(Path(path).suffix.lower())
    if fmt is None:
        raise DoefabError(f"{path}: the extension {Path(path).suffix or '(none)'!r} names no frame format: use "
                          f".npy, .png, .tif/.tiff or a camera raw (.dng, .nef, .cr2, .arw ...), or set "
                          f"pixel_format to one of {', '.join(PIXEL_FORMATS[1:])}")
    return fmt


def expand(patterns: list[str] | str, base: Path, what: str) -> list[Path]:
    """The files ``patterns`` (globs, ``**`` allowed; relative to ``base`` unless absolute) match, each pattern's
    matches sorted by name, in the patterns' order, each file once; an error naming ``what`` and the pattern
    that matches no file."""
    if isinstance(patterns, (str, os.PathLike)):
        patterns = [patterns]
    if not isinstance(patterns, (list, tuple)) or not patterns:
        raise DoefabError(f"{what} must be a file pattern or a list of them (e.g. [\"psf/frame_*.tiff\"]), "
                          f"got {patterns!r}")
    out: list[Path] = []
    seen: set[Path] = set()
    for pattern in patterns:
        if not isinstance(pattern, (str, os.PathLike)) or not str(pattern):
            raise DoefabError(f"{what}: {pattern!r} is not a file pattern: give a path or glob such as "
                              f"\"psf/frame_*.tiff\" (relative to {base})")
        full = str(pattern) if os.path.isabs(pattern) else os.path.join(glob.escape(str(base)), str(pattern))
        found = sorted(Path(p) for p in glob.glob(full, recursive=True) if os.path.isfile(p))
        if not found:
            raise DoefabError(f"{what}: no file matches {str(pattern)!r} (looked in {base}): check the path, "
                              f"which is relative to that folder unless absolute, and the glob")
        for p in found:
            if p not in seen:
                seen.add(p)
                out.append(p)
    return out


def _unreadable(path, fmt: str, exc: BaseException) -> DoefabError:
    return DoefabError(f"{path} cannot be read as {fmt} ({type(exc).__name__}: {exc}): check that the file is a "
                       f"complete frame, or set pixel_format to the format it is in ({', '.join(PIXEL_FORMATS[1:])})")


def _png_header(path: Path) -> tuple[int, int]:
    """(bit depth, colour type) from a PNG's IHDR chunk."""
    with open(path, "rb") as fh:
        head = fh.read(26)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise DoefabError(f"{path} is not a PNG file (no PNG signature): check the file, or set pixel_format to "
                          f"the format it is in")
    return head[24], head[25]


def _read_png(path: Path) -> np.ndarray:
    import imageio.v3 as iio

    bits, colour = _png_header(path)
    if bits not in (8, 16) or colour not in (0, 2):
        kind = {0: "grey", 2: "RGB", 3: "palette", 4: "grey+alpha", 6: "RGBA"}.get(colour, f"type {colour}")
        raise DoefabError(f"{path} is {'an' if bits == 8 else 'a'} {bits}-bit {kind} PNG: frames must be 8- or "
                          f"16-bit grey or 8-bit RGB PNGs without alpha; save the camera's values as a 16-bit TIFF "
                          f"or .npy")
    if bits == 16 and colour == 2:
        raise DoefabError(f"{path} is a 16-bit colour PNG, of which Pillow (the PNG reader) keeps only 8 bits: "
                          f"save the frame as a 16-bit TIFF (tifffile) or .npy")
    return iio.imread(path, extension=".png")


_DNG_TAGS = (50706,)  # DNGVersion
_RAW_PHOTOMETRIC = (32803, 34892)  # CFA, LinearRaw


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        if any(t in page.tags for t in _DNG_TAGS) or any(
                int(getattr(q, "photometric", 0)) in _RAW_PHOTOMETRIC for q in [page, *(page.pages or [])]):
            raise DoefabError(f"{path} is a DNG (a camera raw in a TIFF container): read as a TIFF it gives its "
                              f"preview or its undemosaiced mosaic without the raw's levels: set pixel_format to "
                              f"\"raw\" (or \"auto\" with a .dng name)")
        series = tif.series[0]
        arr, axes = series.asarray(), series.axes
    if arr.ndim == 3 and axes.startswith("S"):  # planar samples (R, G, B planes)
        arr = np.moveaxis(arr, 0, -1)
    if arr.ndim == 3 and "S" in axes and arr.shape[-1] != 3:  # grey or colour with alpha / extra samples
        raise DoefabError(f"{path} holds {arr.shape[-1]} samples per pixel (grey or colour with alpha or extra "
                          f"samples): frames must be grey or R, G, B without alpha: save only the camera's grey or "
                          f"R, G, B values")
    if arr.ndim == 3 and arr.shape[-1] != 3:
        raise DoefabError(f"{path} holds a stack of {arr.shape[0]} images (shape {arr.shape}): write one frame "
                          f"per file (a glob such as \"frame_*.tiff\" takes them all)")
    return arr


def _read_raw(path: Path) -> np.ndarray:
    return raw_data(path).binned


def raw_saturated(path: str | Path, fraction: float = 1.0, pixel_format: str = "auto",
                  white: float | None = None) -> np.ndarray | None:
    """(H/2, W/2, 3) bool: where a raw frame's 2×2 cell holds a photosite of that colour at or above ``fraction``
    of ``white`` (DN; None: the raw's own white level) — a clipped photosite binned with an unclipped one reads
    below the clip level; None for a file that is not a raw.

    Example: ``raw_saturated("frame.dng", 0.98).any()`` is True when any photosite reaches 98 % of full scale."""
    path = Path(path)
    if frame_format(path, pixel_format) != "raw":
        return None
    d = raw_data(path)
    return d.peak >= fraction * (d.white if white is None else float(white))


def raw_black_level(path: str | Path, pixel_format: str = "auto") -> np.ndarray:
    """The black level (DN) a raw file's metadata states for R, G, B (LibRaw's ``black_level_per_channel``
    binned as :func:`bin_bayer` bins the mosaic); zeros for the other formats, which state none."""
    path = Path(path)
    if frame_format(path, pixel_format) != "raw":
        return np.zeros(3)
    return raw_data(path).black.copy()


def read_frame(path: str | Path, pixel_format: str = "auto") -> np.ndarray:
    """One frame as float64 digital numbers, (H, W) or (H, W, 3); an error naming the file when it cannot be read,
    holds non-finite values or has a type or shape that is no camera frame."""
    path = Path(path)
    fmt = frame_format(path, pixel_format)
    if not path.is_file():
        raise DoefabError(f"{path} not found: check the path")
    readers = {"npy": lambda p: np.load(p, allow_pickle=False), "png": _read_png, "tiff": _read_tiff,
               "raw": _read_raw}
    try:
        arr = readers[fmt](path)
    except DoefabError:
        raise
    except Exception as exc:  # each library raises its own types for a damaged or foreign file
        raise _unreadable(path, fmt, exc) from None
    arr = np.asarray(arr)
    if arr.dtype.kind not in "uif":
        raise DoefabError(f"{path} holds {arr.dtype} values: frames must be unsigned or signed integers or floats "
                          f"(digital numbers)")
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[-1] == 3)):
        raise DoefabError(f"{path} has shape {arr.shape}: a frame must be (H, W) monochrome or (H, W, 3) colour")
    out = arr.astype(np.float64)
    if not np.isfinite(out).all():
        raise DoefabError(f"{path} holds non-finite values (NaN or inf): re-export the frame from the camera")
    return out


def _int_scale(dtype: np.dtype, bits: int | None = None) -> float:
    return float(2 ** bits - 1) if bits else float(np.iinfo(dtype).max)


def full_scale(path: str | Path, pixel_format: str = "auto") -> float:
    """The largest digital number the file can hold: ``2**bits - 1`` of an integer file, a raw's white level, 1.0
    for a float file of values ≤ 1 (normalised), ``inf`` for a float file of larger values (no clip level)."""
    path = Path(path)
    fmt = frame_format(path, pixel_format)
    if fmt == "raw":
        return raw_data(path).white
    if fmt == "png":
        return _int_scale(np.dtype(np.uint16), _png_header(path)[0])
    bits = None
    if fmt == "tiff":
        import tifffile

        try:
            with tifffile.TiffFile(path) as tif:
                page, dtype = tif.pages[0], tif.series[0].dtype
                bits = page.bitspersample if dtype.kind in "ui" else None
        except Exception as exc:
            raise _unreadable(path, fmt, exc) from None
    else:
        try:
            dtype = np.load(path, mmap_mode="r", allow_pickle=False).dtype
        except Exception as exc:
            raise _unreadable(path, fmt, exc) from None
    if dtype.kind in "ui":
        return _int_scale(dtype, bits)
    return 1.0 if float(read_frame(path, fmt).max(initial=0.0)) <= 1.0 else math.inf


def stated_white_level(path: str | Path, pixel_format: str = "auto", key: str = "white_level") -> float:
    """The sensor's clipping level (DN) a file states: its :func:`full_scale`, or an error naming ``key`` (the
    setting that gives it) where the file states none: a float file of values above 1, or an integer file wider
    than 16 bits (whose full scale, e.g. 4294967295 for 32 bits, no sensor reaches).

    Example: ``stated_white_level("frame.tiff")`` is 65535.0 for a 16-bit TIFF."""
    top = full_scale(path, pixel_format)
    if math.isinf(top):
        raise DoefabError(f"{path} holds floats above 1 and so states no white level: give {key} (the sensor's "
                          f"clipping level in the file's units), or save the frame scaled to [0, 1]")
    if top > 2**SENSOR_BITS - 1:
        raise DoefabError(f"{path} holds integers wider than {SENSOR_BITS} bits, whose full scale {top:.0f} DN is "
                          f"no sensor's clipping level: give {key} (e.g. 4095 for 12-bit, 16383 for 14-bit, 65535 "
                          f"for 16-bit values)")
    return top


def mean_frames(paths, pixel_format: str = "auto") -> tuple[np.ndarray, int]:
    """The mean of the frames ``paths`` (float64 DN) and their number; an error naming the first file whose shape
    differs from the first file's."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise DoefabError("no frames to average: give at least one file")
    total = read_frame(paths[0], pixel_format)
    for p in paths[1:]:
        frame = read_frame(p, pixel_format)
        if frame.shape != total.shape:
            raise DoefabError(f"{p} is {_shape(frame.shape)} but {paths[0]} is {_shape(total.shape)}: every frame "
                              f"of one recording must have the same size and channels (re-record or remove it)")
        total += frame
    return total / len(paths), len(paths)


def _shape(shape) -> str:
    return f"{shape[1]}×{shape[0]} px" + (f" × {shape[2]} channels" if len(shape) == 3 else "")


def write_frame(path: str | Path, array, bits: int = 16) -> Path:
    """Write ``array`` (DN, (H, W) or (H, W, 3)) as an integer TIFF (``.tif``/``.tiff``), PNG or ``.npy`` of
    ``bits`` (8 or 16) per sample, rounded, atomically; an error when a value does not fit."""
    path = Path(path)
    ext = path.suffix.lower()
    if bits not in (8, 16):
        raise DoefabError(f"bits must be 8 or 16, got {bits!r}")
    if ext not in (".tif", ".tiff", ".png", ".npy"):
        raise DoefabError(f"{path}: write_frame writes .tif/.tiff, .png or .npy frames, not {ext or '(none)'!r}")
    a = np.asarray(array, dtype=np.float64)
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[-1] == 3)):
        raise DoefabError(f"a frame must be (H, W) or (H, W, 3), got shape {a.shape}")
    top = 2 ** bits - 1
    if not np.isfinite(a).all() or a.min(initial=0) < 0 or a.max(initial=0) > top:
        raise DoefabError(f"{path}: a {bits}-bit frame holds 0 … {top} DN, the array spans "
                          f"{np.nanmin(a):g} … {np.nanmax(a):g}: clip or rescale it (or write 16 bits)")
    data = np.rint(a).astype(np.uint16 if bits == 16 else np.uint8)
    buf = io.BytesIO()
    if ext == ".npy":
        np.save(buf, data, allow_pickle=False)
    elif ext == ".png":
        import imageio.v3 as iio

        if bits == 16 and data.ndim == 3:
            raise DoefabError(f"{path}: a 16-bit colour PNG cannot be written by Pillow: write a .tiff instead")
        buf.write(iio.imwrite("<bytes>", data, extension=".png"))
    else:
        import tifffile

        tifffile.imwrite(buf, data, photometric="rgb" if data.ndim == 3 else "minisblack")
    return atomic_write_bytes(path, buf.getvalue())
