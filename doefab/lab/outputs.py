"""Reconstructions written in the formats other programs open, each file atomically (a temporary name in the
target's folder, then ``os.replace``: a reader never sees half a file, and a failed write leaves none).

=====================  =====================================================================================
result                 files
=====================  =====================================================================================
HDR radiance [3, H, W] OpenEXR (:func:`write_hdr_exr`): linear, half float, one ``RGB`` channel group, the
                       radiance as reconstructed (1 = the clipping level of a full exposure: the plain half clips at 2;
                       up to 2^8); a tone-mapped 8-bit PNG (:func:`write_tonemapped_png`, Reinhard's global operator)
spectra [C, H, W]      an ENVI cube (:func:`write_envi`, Spectral Python: float32, band-interleaved by line,
                       ``wavelength`` in nm, ``wavelength units = nm``; :func:`write_envi_rows` writes it row block
                       by row block); an sRGB preview (:func:`write_srgb_preview`, CIE 1931)
depth [H, W], metres   float32 TIFF in metres (:func:`write_depth_tiff`); 16-bit PNG in millimetres
                       (:func:`write_depth_png16`: rounded to 1 mm, clipped to 0 … 65.535 m); a colour preview
                       (:func:`write_depth_preview`, matplotlib's ``viridis``)
=====================  =====================================================================================

The previews are for looking at, not for measuring: the camera's RGB is treated as linear sRGB (Rec. 709
primaries), which it is only approximately.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from pathlib import Path

import numpy as np

from doefab.applications import has
from doefab.errors import DoefabError
from doefab.io import apply_umask

__all__ = ["write_hdr_exr", "write_tonemapped_png", "write_envi", "write_srgb_preview", "write_depth_tiff",
           "write_depth_png16", "write_depth_preview", "reinhard", "reinhard_stats", "srgb_encode", "spectra_to_xyz",
           "MAX_DEPTH_PNG_M", "write_result", "result_names", "write_envi_rows", "write_xyz_preview",
           "write_result_rows"]

MAX_DEPTH_PNG_M = 65.535  # the 16-bit PNG's largest depth (65535 mm)
REC709_LUMA = (0.2126, 0.7152, 0.0722)  # luminance of linear Rec. 709 / sRGB primaries
_BAND = 256  # rows a preview is computed over at once: its float work stays a band, not the image


@contextlib.contextmanager
def _atomic(path, also: tuple[str, ...] = ()):
    """Yield a temporary path beside ``path`` (same suffix) for a library to write; on success it (and the
    sibling files with the suffixes ``also``, written beside it by the library) replace the targets."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    pairs = [(tmp.with_suffix(s), path.with_suffix(s)) for s in also] + [(tmp, path)]  # the named file last
    try:
        yield tmp
        for src, dst in pairs:
            apply_umask(src)  # mkstemp makes 0600; a result is the user's like any file they write
            os.replace(src, dst)
    finally:
        for src, _ in pairs:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(src)


def _image(name: str, x, channels: int | None) -> np.ndarray:
    """``x`` as a finite float array [channels, H, W] (channels None: [H, W]), or one error naming it."""
    a = np.asarray(x)
    want = "[H, W]" if channels is None else f"[{channels or 'C'}, H, W]"
    ok = a.ndim == 2 if channels is None else (a.ndim == 3 and (channels == 0 or a.shape[0] == channels))
    if not ok or a.dtype.kind not in "fiu" or 0 in a.shape:
        raise DoefabError(f"{name} must be a {want} array of numbers, got {a.dtype} {a.shape}")
    if not np.isfinite(a).all():
        raise DoefabError(f"{name} holds NaN or infinite values: nothing to write")
    return a


def write_hdr_exr(path, rgb) -> Path:
    """Linear HDR radiance [3, H, W] (≥ 0) as a half-float OpenEXR file (ZIP-compressed scanlines, one ``RGB``
    channel group); values above half float's largest (65504) are refused. Returns the path."""
    import OpenEXR

    a = _image("the HDR image", rgb, 3)
    if a.min() < 0 or a.max() > 65504:
        raise DoefabError(f"the HDR image spans {a.min():g} … {a.max():g}: half-float OpenEXR holds 0 … 65504 "
                          f"(linear radiance ≥ 0)")
    pixels = np.ascontiguousarray(np.moveaxis(a, 0, -1).astype(np.float16))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with _atomic(path) as tmp, OpenEXR.File(header, {"RGB": pixels}) as f:
        f.write(str(tmp))
    return Path(path)


def _luminance(rgb) -> np.ndarray:
    return np.tensordot(REC709_LUMA, np.asarray(rgb, np.float64), axes=1)


def reinhard_stats(rgb, key: float = 0.18) -> tuple[float, float]:
    """(``key`` over the log-average luminance, the largest scaled luminance²) of [3, H, W] radiance: the image's
    two numbers that :func:`reinhard` needs, gathered a band of rows at a time."""
    total, top = 0.0, 0.0
    for r in range(0, rgb.shape[1], _BAND):
        lum = _luminance(rgb[:, r:r + _BAND])
        total, top = total + float(np.log(1e-6 + lum).sum()), max(top, float(lum.max()))
    scale = key / math.exp(total / (rgb.shape[1] * rgb.shape[2]))
    return scale, max(scale * top, 1e-12) ** 2


def reinhard(rgb, key: float = 0.18, stats: tuple[float, float] | None = None) -> np.ndarray:
    """Reinhard et al. (2002)'s global operator on luminance: ``L`` (Rec. 709 weights) scaled by ``key`` over
    its log-average, compressed by ``Ls (1 + Ls / Lw²) / (1 + Ls)`` (``Lw``: the largest scaled luminance, which
    maps to 1), each pixel's RGB scaled by the same factor; [3, H, W] → [3, H, W] display-linear in [0, 1].
    ``stats``: the whole image's :func:`reinhard_stats` when ``rgb`` is a band of its rows."""
    a = np.asarray(rgb, np.float64)
    scale, lw2 = reinhard_stats(a, key) if stats is None else stats
    lum = _luminance(a)
    ls = scale * lum
    ld = ls * (1 + ls / lw2) / (1 + ls)
    return np.clip(a * (ld / np.maximum(lum, 1e-12))[None], 0.0, 1.0)


def srgb_encode(linear) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of display-linear values in [0, 1]."""
    x = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _write_png8(path, shape: tuple[int, int], rows) -> Path:
    """An 8-bit RGB PNG (imageio) of ``shape`` (H, W); ``rows(r0, r1)`` gives the encoded values in [0, 1] of
    rows r0 … r1 as [3, r1 − r0, W], so the float work stays a band of rows."""
    import imageio.v3 as iio

    h, w = shape
    data = np.empty((h, w, 3), np.uint8)
    for r in range(0, h, _BAND):
        band = rows(r, min(h, r + _BAND))
        data[r:r + band.shape[1]] = np.rint(np.moveaxis(np.clip(band, 0.0, 1.0), 0, -1) * 255)
    with _atomic(path) as tmp:
        iio.imwrite(tmp, data, extension=".png")
    return Path(path)


def write_tonemapped_png(path, rgb) -> Path:
    """HDR radiance [3, H, W] tone-mapped for a screen: :func:`reinhard`, then :func:`srgb_encode`, 8 bits."""
    a = _image("the HDR image", rgb, 3)
    stats = reinhard_stats(a)
    return _write_png8(path, a.shape[1:], lambda r0, r1: srgb_encode(reinhard(a[:, r0:r1], stats=stats)))


def write_envi(path, cube, wavelengths_m) -> Path:
    """A spectral cube [C, H, W] as an ENVI file pair (:func:`write_envi_rows`). Returns the header's path."""
    a = _image("the spectral cube", cube, 0)
    return write_envi_rows(path, [(0, a)], a.shape, wavelengths_m)


def write_envi_rows(path, blocks, shape: tuple[int, int, int], wavelengths_m) -> Path:
    """A spectral cube of ``shape`` (C, H, W) as an ENVI file pair, from ``blocks``: ``(row, [C, rows, W])`` top
    to bottom, every row once (e.g. ``doefab.lab.reconstruct.iter_tiled``), so the cube need not be in memory.
    ``path`` is the header (``.hdr``, written by Spectral Python's ``envi.create_image``: float32, little-endian,
    band-interleaved by line, ``wavelength`` in nm to 6 significant digits, ``wavelength units = nm``); the data
    is the ``.img`` beside it. Returns the header's path."""
    from spectral.io import envi

    c, h, w = (int(v) for v in shape)
    nm = [float(f"{x * 1e9:.6g}") for x in np.asarray(wavelengths_m, np.float64).reshape(-1)]
    if len(nm) != c or not all(100 <= x <= 20000 for x in nm):
        raise DoefabError(f"wavelengths_m must give one wavelength in metres per band ({c} bands, e.g. 5.5e-07 for "
                          f"550 nm), got {len(nm)} values")
    path = Path(path)
    if path.suffix != ".hdr":
        raise DoefabError(f"{path}: an ENVI cube is named by its header: give a path ending in .hdr")
    meta = {"wavelength": nm, "wavelength units": "nm", "description": "doefab reconstruct: spectral radiance"}
    with _atomic(path, also=(".img",)) as tmp:
        envi.create_image(str(tmp), meta, shape=(h, w, c), dtype=np.float32, interleave="bil", ext=".img",
                          byteorder=0, force=True)
        done = 0
        with open(tmp.with_suffix(".img"), "r+b") as fh:
            for row, block in blocks:
                b = _image("the spectral cube", block, c)
                if row != done or b.shape[2] != w or row + b.shape[1] > h:
                    raise DoefabError(f"spectral rows {row}–{row + b.shape[1]} of width {b.shape[2]} do not continue "
                                      f"a {c} × {h} × {w} cube at row {done}")
                fh.seek(row * c * w * 4)
                fh.write(np.ascontiguousarray(np.moveaxis(b, 0, 1), dtype="<f4").tobytes())
                done += b.shape[1]
        if done != h:
            raise DoefabError(f"the spectral cube got {done} of its {h} rows")
    return path


def spectra_to_xyz(cube, wavelengths_m) -> np.ndarray:
    """CIE 1931 XYZ [3, H, W] of a spectral radiance cube [C, H, W]: the 2° colour-matching functions
    (colour-science) interpolated to the bands, weighted by each band's width (trapezoid rule)."""
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    nm = np.asarray(wavelengths_m, np.float64).reshape(-1) * 1e9
    xyz_bar = np.stack([np.interp(nm, cmfs.wavelengths, cmfs.values[:, k], left=0, right=0) for k in range(3)])
    width = np.gradient(nm) if nm.size > 1 else np.ones(1)
    return np.tensordot(xyz_bar * width[None], np.asarray(cube, np.float64), axes=1)


def write_srgb_preview(path, cube, wavelengths_m, percentile: float = 99.0) -> Path:
    """An sRGB view of a spectral cube [C, H, W]: :func:`spectra_to_xyz`, exposed so the ``percentile``-th
    percentile of Y is 1, converted to sRGB for a D65 white (colour-science's ``XYZ_to_sRGB``, no chromatic
    adaptation: the cube is radiance as seen), clipped and encoded, 8 bits."""
    return write_xyz_preview(path, spectra_to_xyz(_image("the spectral cube", cube, 0), wavelengths_m), percentile)


def write_xyz_preview(path, xyz, percentile: float = 99.0) -> Path:
    """CIE XYZ [3, H, W] as an 8-bit sRGB preview (:func:`write_srgb_preview`)."""
    import colour

    xyz = np.asarray(xyz)
    scale = float(np.percentile(xyz[1], percentile))
    scale = scale if scale > 0 else 1.0
    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]

    def rows(r0, r1):
        band = np.moveaxis(xyz[:, r0:r1].astype(np.float64) / scale, 0, -1)
        rgb = colour.XYZ_to_sRGB(band, illuminant=d65, chromatic_adaptation_transform=None, apply_cctf_encoding=False)
        return srgb_encode(np.moveaxis(rgb, -1, 0))

    return _write_png8(path, xyz.shape[1:], rows)


def _depth(depth_m) -> np.ndarray:
    d = _image("the depth map", depth_m, None)
    if d.min() < 0:
        raise DoefabError(f"the depth map holds negative depths (down to {d.min():g} m): depths are ≥ 0 m")
    return d


def write_depth_tiff(path, depth_m) -> Path:
    """A depth map [H, W] in metres as a single-channel float32 TIFF (tifffile, zlib-compressed)."""
    import tifffile

    d = _depth(depth_m).astype(np.float32)
    with _atomic(path) as tmp:
        tifffile.imwrite(tmp, d, photometric="minisblack", compression="zlib",
                         description="doefab reconstruct: depth in metres (float32)")
    return Path(path)


def write_depth_png16(path, depth_m) -> Path:
    """A depth map [H, W] as a 16-bit grey PNG in millimetres: ``round(1000 · depth)``, clipped to 0 … 65535
    (depths beyond 65.535 m read as 65535)."""
    import imageio.v3 as iio

    mm = np.clip(np.rint(_depth(depth_m).astype(np.float64) * 1000.0), 0, 65535).astype(np.uint16)
    with _atomic(path) as tmp:
        iio.imwrite(tmp, mm, extension=".png")
    return Path(path)


def write_depth_preview(path, depth_m, near_m: float | None = None, far_m: float | None = None) -> Path:
    """A depth map [H, W] through matplotlib's ``viridis`` colour map from ``near_m`` (dark) to ``far_m``
    (yellow; default: the map's own range), 8-bit RGB PNG."""
    from matplotlib import colormaps

    d = _depth(depth_m)
    lo = float(d.min()) if near_m is None else float(near_m)
    hi = float(d.max()) if far_m is None else float(far_m)
    span = hi - lo if hi > lo else np.inf  # one depth: the map's dark end

    def rows(r0, r1):
        t = np.clip((d[r0:r1] - lo) / span, 0.0, 1.0)
        return np.moveaxis(colormaps["viridis"](t)[..., :3], -1, 0)

    return _write_png8(path, d.shape, rows)


def result_names(task: str, stem: str) -> list[str]:
    """The files :func:`write_result` writes for ``task`` and a capture named ``stem``; ``stem.png`` is always
    the picture to look at."""
    if has(task, "highlights"):  # radiance
        return [f"{stem}.exr", f"{stem}.png"]
    if has(task, "spectral"):
        return [f"{stem}.hdr", f"{stem}.img", f"{stem}.png"]
    return [f"{stem}.depth_m.tiff", f"{stem}.depth_mm.png", f"{stem}.png"]


def write_result(task: str, result, folder, stem: str, wavelengths_m=None, depth_range_m=None) -> list[Path]:
    """Every file of a task's result (:func:`result_names`) in ``folder``: HDR radiance [3, H, W] → EXR and the
    tone-mapped PNG; spectra [C, H, W] → ENVI (``wavelengths_m``) and the sRGB preview; depth [H, W] in metres →
    float32 TIFF, 16-bit millimetre PNG and the preview over ``depth_range_m`` (near, far)."""
    folder = Path(folder)
    names = [folder / n for n in result_names(task, stem)]
    if has(task, "highlights"):
        write_hdr_exr(names[0], result)
        write_tonemapped_png(names[1], result)
    elif has(task, "spectral"):
        write_envi(names[0], result, wavelengths_m)
        write_srgb_preview(names[2], result, wavelengths_m)
    else:
        write_depth_tiff(names[0], result)
        write_depth_png16(names[1], result)
        write_depth_preview(names[2], result, *(depth_range_m or (None, None)))
    return names


def write_result_rows(task: str, blocks, shape: tuple[int, int, int], folder, stem: str, wavelengths_m=None,
                      depth_range_m=None) -> list[Path]:
    """:func:`write_result` from ``blocks`` of rows (``(row, [C, rows, W])`` top to bottom, e.g.
    ``doefab.lab.reconstruct.iter_tiled``) of a result of ``shape`` (C, H, W): spectra go to the ENVI file as
    they come, with their XYZ kept for the preview (3 floats per pixel, not C); HDR and depth are gathered first
    (OpenEXR, TIFF and PNG write whole images)."""
    c, h, w = shape
    if not has(task, "spectral"):
        out = np.empty((c, h, w), np.float32)
        for row, block in blocks:
            out[:, row:row + block.shape[1]] = block
        return write_result(task, out[0] if has(task, "depth") else out, folder, stem, wavelengths_m, depth_range_m)
    names = [Path(folder) / n for n in result_names(task, stem)]
    xyz = np.empty((3, h, w), np.float32)

    def keep_xyz():
        for row, block in blocks:
            xyz[:, row:row + block.shape[1]] = spectra_to_xyz(block, wavelengths_m)
            yield row, block

    write_envi_rows(names[0], keep_xyz(), shape, wavelengths_m)
    write_xyz_preview(names[2], xyz)
    return names
