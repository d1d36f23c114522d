"""A lab's recordings of a part of known errors, simulated: what the tests, the tutorial and the diagnosis benchmark
calibrate from, written as a lab writes them (16-bit TIFFs and a recordings file).

- PSFs: the part's coded and plain halves (``doefab.tolerance.judge.PSFJudge`` at ``supersample`` cells per DOE
  pixel) at the bands and planes asked, each computed on the whole frame (``size`` pixels, default 2K), moved by
  the source's sub-pixel offset ``shift_px`` (row, column; a Fourier shift), scaled so that a frame's expected
  light is ``photons`` photo-electrons, with shot (Poisson) and read noise (Gaussian, ``read_noise_e``);
- the camera: a black level of ``BLACK_LEVEL_DN``, 16 bits, a gain (electrons per DN) of 1 unless the brightest
  expected PSF pixel would then pass ``PEAK_FRACTION`` of the range (then raised to keep it there);
- dark frames (black level and read noise) for the PSFs and for the wall;
- white-wall pairs (``wall``): with one half open, the wall's light (half the range) reaches that half's view
  and, through the sensor's ``crosstalk`` (α_l→r, α_r→l; Eq. 29, ``mix_crosstalk``, left = plain view, right =
  coded view), the other view;
- ``recordings.toml`` pointing at them (relative paths) and ``truth.json``: the part's errors, the offset, the
  gain, the black level and the crosstalk the recordings were made with.
"""

from __future__ import annotations

import itertools
import json
import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from doefab import validate as v
from doefab.errors import DoefabError
from doefab.io import atomic_write_json, atomic_write_text
from doefab.lab.frames import write_frame
from doefab.lab.recordings import band_index, plane_index

__all__ = ["write_lab_recordings", "BLACK_LEVEL_DN", "PEAK_FRACTION", "WALL_FRACTION"]

BLACK_LEVEL_DN = 64.0
PEAK_FRACTION = 0.7  # the brightest expected PSF pixel stays below this fraction of the 16-bit range
WALL_FRACTION = 0.5  # the open view's white-wall level, fraction of the 16-bit range
_TOP_DN = 65535.0


def _select(name: str, asked, have, index, unit: str, scale: float) -> list[int]:
    """Indices into the design's ``have`` of the values ``asked`` (all when None); an error listing ``have``."""
    if asked is None:
        return list(range(len(have)))
    out = []
    for a in np.atleast_1d(np.asarray(asked, dtype=np.float64)).tolist():
        i = index(a, have)
        if i is None:
            listed = ", ".join("inf" if math.isinf(h) else f"{h * scale:g}" for h in have)
            raise DoefabError(f"{name} = {a:g} m is not one of the design's: use some of {listed} {unit}")
        out.append(i)
    return sorted(set(out))


def _check_args(folder: Path, photons, read_noise_e, shift_px, frames, dark_frames, crosstalk, seed) -> None:
    from doefab.imaging.crosstalk import check_pair

    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise DoefabError(f"folder {folder} is {'a file' if not folder.is_dir() else 'not empty'}: give a new or "
                          f"empty folder for the recordings")
    v.number_in("photons", photons, 0, 1e15, unit="photo-electrons per frame", lo_open=True)
    v.number_in("read_noise_e", read_noise_e, 0, 1e4, unit="electrons rms")
    if len(tuple(shift_px)) != 2:
        raise DoefabError(f"shift_px must be (rows, columns) in pixels, got {shift_px!r}")
    for s in shift_px:
        v.number_in("shift_px", s, -1e4, 1e4, unit="pixels")
    v.number_in("frames", frames, 1, 10000, integer=True)
    v.number_in("dark_frames", dark_frames, 0, 10000, integer=True)
    if len(tuple(crosstalk)) != 2:
        raise DoefabError(f"crosstalk must be (α_l→r, α_r→l), two fractions, got {crosstalk!r}: e.g. "
                          f"(0.05, 0.04)")
    check_pair(*crosstalk, name="crosstalk α_l→r, crosstalk α_r→l")
    v.seed("seed", seed)


def _part_psfs(design_dir: Path, err, supersample: int, bands: list, planes: list, size: int) -> dict:
    """{"coded", "plain": (planes, bands, size, size) float64} the part's PSFs at the bands and planes chosen."""
    import torch

    from doefab.design.design import Design
    from doefab.fabrication.process import mask_count
    from doefab.tolerance.judge import PSFJudge, alignment_chain

    d = Design.load(design_dir)
    sub = replace(d, wavelengths=tuple(d.wavelengths[i] for i in bands), depths=tuple(d.depths[i] for i in planes))
    judge = PSFJudge(sub, supersample, chain=alignment_chain(design_dir, mask_count(d.n_levels)))
    with torch.no_grad():
        got = judge.psfs(err, halves=("coded", "uncoded"), kernel=size)
    return {"coded": got["coded"].double().numpy(), "plain": got["uncoded"].double().numpy()}


def _shifted(psf: np.ndarray, shift_px) -> np.ndarray:
    """``psf`` moved by ``shift_px`` (rows, columns; Fourier shift), negative ringing clipped, summing to 1."""
    from scipy.ndimage import fourier_shift

    moved = np.fft.ifft2(fourier_shift(np.fft.fft2(psf), tuple(shift_px))).real
    moved = np.clip(moved, 0.0, None)
    return moved / moved.sum()


def _expose(expected_e: np.ndarray, gain: float, read_noise_e: float, rng) -> np.ndarray:
    """One 16-bit frame (DN) of ``expected_e`` photo-electrons: shot noise, read noise, black level."""
    e = rng.poisson(expected_e).astype(np.float64) + rng.normal(0.0, read_noise_e, expected_e.shape)
    return np.clip(np.rint(e / gain + BLACK_LEVEL_DN), 0, _TOP_DN)


def _toml_list(paths, folder: Path) -> str:
    """A TOML array of ``paths`` relative to ``folder``."""
    return "[" + ", ".join(json.dumps(Path(p).relative_to(folder).as_posix()) for p in paths) + "]"


def write_lab_recordings(folder, design_dir, err=None, *, supersample: int = 2, wavelengths_m=None, depths_m=None,
                         photons: float = 1e6, read_noise_e: float = 2.0, shift_px=(0.0, 0.0), frames: int = 4,
                         dark_frames: int = 2, wall: bool = True, crosstalk=(0.05, 0.04), size: int | None = None,
                         seed: int = 0) -> Path:
    """Record the part of errors ``err`` (``PartErrors``; None: a nominal part) made from ``design_dir`` as a lab
    would, into the new or empty ``folder``; returns the recordings file's path (``folder/recordings.toml``).

    ``wavelengths_m``/``depths_m``: the design's bands and planes to record (default all); ``photons``: expected
    photo-electrons of each PSF frame; ``shift_px``: the source's offset from the chief ray (rows, columns);
    ``frames``/``dark_frames``: per recording; ``crosstalk``: (α_l→r, α_r→l) of the sensor's wall frames;
    ``size``: frame side in pixels (default twice the design's kernel). Everything is checked before any file is
    written."""
    from doefab.design.design import Design, design_folder_of
    from doefab.tolerance.errors import PartErrors

    folder, design_dir = Path(folder), design_folder_of(design_dir)
    _check_args(folder, photons, read_noise_e, shift_px, frames, dark_frames, crosstalk, seed)
    d = Design.load(design_dir)
    kernel = d.kernel_size
    size = 2 * kernel if size is None else v.number_in("size", size, kernel, 8192, integer=True, unit="pixels")
    bands = _select("wavelengths_m", wavelengths_m, d.wavelengths, band_index, "nm", 1e9)
    planes = _select("depths_m", depths_m, d.depths, plane_index, "m", 1.0)
    err = PartErrors() if err is None else err
    if not isinstance(err, PartErrors):
        raise DoefabError(f"err must be a PartErrors (SI units) or None, got {type(err).__name__}")
    psfs = {h: _shifted_all(p, shift_px) for h, p in _part_psfs(design_dir, err, supersample, bands, planes,
                                                                  size).items()}
    peak_e = photons * max(float(p.max()) for p in psfs.values())
    gain = max(1.0, peak_e / (PEAK_FRACTION * (_TOP_DN - BLACK_LEVEL_DN)))
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    rel_design = Path(os.path.relpath(design_dir.resolve(), folder.resolve())).as_posix()
    toml = [f"design = {json.dumps(rel_design)}", 'pixel_format = "tiff"', f"black_level = {BLACK_LEVEL_DN:g}", ""]
    dark = _darks(folder / "psf", dark_frames, size, gain, read_noise_e, rng)
    for half, stack in psfs.items():
        for (pi, zi), (bi, wi) in itertools.product(enumerate(planes), enumerate(bands)):
            paths = [write_frame(folder / "psf" / f"{half}_b{wi}_d{zi}_{k}.tiff",
                                 _expose(photons * stack[pi, bi], gain, read_noise_e, rng)) for k in range(frames)]
            depth = d.depths[zi]
            toml += ["[[psf]]", f'half = "{half}"', f'view = "{half}"',
                     f"depth_m = {json.dumps('inf') if math.isinf(depth) else repr(float(depth))}",
                     f"wavelength_nm = {d.wavelengths[wi] * 1e9!r}", f"frames = {_toml_list(paths, folder)}",
                     *([f"dark = {_toml_list(dark, folder)}"] if dark else []), ""]
    if wall:
        toml += _write_walls(folder, frames, dark_frames, size, gain, read_noise_e, crosstalk, rng)
    atomic_write_json(folder / "truth.json", {
        "design": str(design_dir.resolve()), "errors": err.to_json(), "supersample": supersample,
        "wavelengths_m": [d.wavelengths[i] for i in bands],
        "depths_m": [v.distance_record(d.depths[i]) for i in planes],
        "shift_px": [float(s) for s in shift_px], "photons_per_frame": float(photons), "gain_e_per_dn": gain,
        "black_level_dn": BLACK_LEVEL_DN, "read_noise_e": float(read_noise_e), "crosstalk": list(crosstalk),
        "wall_level_e": WALL_FRACTION * (_TOP_DN - BLACK_LEVEL_DN) * gain, "size_px": size, "seed": seed})
    return atomic_write_text(folder / "recordings.toml", "\n".join(toml))


def _shifted_all(stack: np.ndarray, shift_px) -> np.ndarray:
    out = np.empty_like(stack)
    for idx in np.ndindex(stack.shape[:2]):
        out[idx] = _shifted(stack[idx], shift_px)
    return out


def _write_walls(folder: Path, frames: int, dark_frames: int, size: int, gain: float, read_noise_e: float,
                 crosstalk, rng) -> list[str]:
    """The white-wall pairs (each half open in turn, both views, Eq. 29's crosstalk) and their darks; their
    recordings-file lines."""
    from doefab.imaging.crosstalk import mix_crosstalk

    dark = _darks(folder / "wall", dark_frames, size, gain, read_noise_e, rng)
    level = WALL_FRACTION * (_TOP_DN - BLACK_LEVEL_DN) * gain  # electrons of the open view
    toml = []
    for half in ("coded", "plain"):
        clean = np.full((size, size), level), np.zeros((size, size))  # (open view, closed view)
        left, right = mix_crosstalk(*(clean[::-1] if half == "coded" else clean), *crosstalk)  # left: plain view
        toml += ["[[wall]]", f'half = "{half}"']
        for view, light in (("coded_view", right), ("plain_view", left)):
            paths = [write_frame(folder / "wall" / f"{half}_open_{view}_{k}.tiff",
                                 _expose(light, gain, read_noise_e, rng)) for k in range(frames)]
            toml.append(f"{view} = {_toml_list(paths, folder)}")
        toml += [f"dark = {_toml_list(dark, folder)}", ""] if dark else [""]
    return toml


def _darks(where: Path, n: int, size: int, gain: float, read_noise_e: float, rng) -> list[Path]:
    return [write_frame(where / f"dark_{k}.tiff", _expose(np.zeros((size, size)), gain, read_noise_e, rng))
            for k in range(n)]
