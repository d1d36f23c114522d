"""``doefab calibrate``: a fabricated part's own recordings → ``psf_pair.npz``, ``crosstalk.json``,
``calibration.html``.

Each ``[[psf]]`` recording is averaged, its darks' mean (or the file's ``black_level``, else a raw's own level per
channel: ``framechecks.frame_black``) subtracted, registered to
the design's nominal PSF of that half, band and plane (:func:`doefab.lab.measure.register`; the shift is the
source's or the sensor's offset, not a fab error, and is reported), resampled onto the design's kernel with
the chief ray on its centre pixel, and normalised to the nominal half's share of the light over that kernel.
``channels = "rgb"`` frames give one PSF per channel: R, G and B are the design's three bands in order of
decreasing wavelength. ``[[wall]]`` pairs give the per-column crosstalk (Eq. 30–31) with standard errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.imaging.crossratios import check_pair
from doefab.lab.measure import extract, normalise, photon_transfer, register, wall_ratios
from doefab.lab.recordings import Recordings, band_index, check_recordings, plane_index, recordings_sha256
from doefab.lab.viewcheck import template_fits, view_warnings

__all__ = ["calibrate", "measure_recordings", "write_calibration", "Calibration", "psf_grid", "nominal_psfs",
           "registration_size", "calibrate_recording", "measure_walls", "rgb_bands", "PSFGrid"]

PAIR_HALF = {"coded": "coded", "plain": "uncoded"}  # a recording's half → the PSFPair's


@dataclass
class PSFGrid:
    """Which design planes and bands were recorded (indices into the design's lists, in its order) and, for each
    (half, plane, band), the recording and its colour channel (None: a monochrome frame)."""

    planes: list[int]
    bands: list[int]
    entries: dict


def rgb_bands(wavelengths_m) -> list[int]:
    """The design bands that the R, G and B channels record: its three bands in order of decreasing wavelength."""
    return sorted(range(len(wavelengths_m)), key=lambda i: -wavelengths_m[i])


def _bands_of(r, wavelengths_m) -> list[tuple[int, int | None]]:
    """[(band index, channel)] a recording gives."""
    if r.channels == "rgb":
        return [(b, c) for c, b in enumerate(rgb_bands(wavelengths_m))]
    return [(band_index(r.wavelength_m, wavelengths_m), None)]


def _name(z: float, w: float) -> str:
    return f"{'inf' if math.isinf(z) else f'{z:g} m'}, {w * 1e9:g} nm"


def psf_grid(rec: Recordings, wavelengths_m, depths_m) -> PSFGrid:
    """The (planes × bands) grid the ``[[psf]]`` recordings form for both halves. Refuses, in one error, a recording
    whose half is not its view (the crosstalk's leak: that is what ``[[wall]]`` pairs measure), two recordings of
    one (half, plane, band), and a grid with holes (every missing (half, depth, band) named)."""
    problems, entries = [], {}
    for r in rec.psf:
        if r.half != r.view:
            problems.append(f"{r.name}: half = {r.half!r} but view = {r.view!r}: the other view of a blocked half is "
                            f"the sensor's crosstalk, which the white-wall pairs measure: record it as a [[wall]] "
                            f"(half, coded_view, plain_view) and keep [[psf]] to view = half")
            continue
        z = plane_index(r.depth_m, depths_m)
        bands = _bands_of(r, wavelengths_m)
        if z is None or any(b is None for b, _ in bands) or (r.channels == "rgb" and len(wavelengths_m) != 3):
            problems.append(f"{r.name}: its depth or band is none of the design's (check_recordings names the fix)")
            continue
        for b, c in bands:
            key = (r.half, z, b)
            if key in entries:
                problems.append(f"{r.name} records {r.half} at {_name(depths_m[z], wavelengths_m[b])} as "
                                f"{entries[key][0].name} does: list all frames of one source in one recording")
            entries[key] = (r, c)
    planes = sorted({k[1] for k in entries})
    bands = sorted({k[2] for k in entries})
    missing = [f"{h} at {_name(depths_m[z], wavelengths_m[b])}" for h in PAIR_HALF for z in planes for b in bands
               if (h, z, b) not in entries]
    if missing:
        problems.append(f"the [[psf]] recordings are no full grid of both halves × planes × bands: missing "
                        f"{'; '.join(missing)}: record them, or leave out the planes/bands they belong to")
    if not entries and not problems:
        problems.append("no [[psf]] recording: add point-source recordings of both halves (half = view)")
    if problems:
        raise DoefabError(f"{rec.path}: " + "\n  - ".join(["the PSF recordings cannot be calibrated:"] + problems))
    return PSFGrid(planes, bands, entries)


def registration_size(design, grid: PSFGrid, kernel: int) -> int:
    """The side (odd, pixels) of the nominal PSFs the registration matches: ``measure.register_size(kernel)``,
    held inside the alias-free field at the grid's shortest wavelength (λ s / (2 · DOE pitch) from the chief ray),
    and never below the kernel."""
    from doefab.lab.measure import register_size

    lam = min(design.wavelengths[b] for b in grid.bands)
    most = int(2 * (design.camera.alias_free_px(lam) - 0.5))
    return max(kernel, min(register_size(kernel), most - (most + 1) % 2))


def nominal_psfs(design, grid: PSFGrid, kernel: int) -> dict:
    """{half: (planes, bands, K, K) float64} PSFs of the design's L-level part (no fab error) on its camera."""
    import torch

    from doefab.fabrication.levels import levels_to_height
    from doefab.optics.psf import PSFPlan

    plan = PSFPlan(design.camera, [design.wavelengths[b] for b in grid.bands],
                   [design.depths[z] for z in grid.planes], kernel, halves=("coded", "uncoded"))
    with torch.no_grad():
        pair = plan(levels_to_height(design.levels, design.camera, design.n_levels))
    return {"coded": pair.coded.double().numpy(), "uncoded": pair.uncoded.double().numpy()}


def _read(paths, fmt: str):
    """The frames ``paths`` averaged (``doefab.lab.framechecks.read_set``; checked before, so a problem here is
    raised)."""
    from doefab.lab.framechecks import read_set

    problems: list[str] = []
    got = read_set(paths, fmt, problems)
    if problems or got is None:
        raise DoefabError(problems[0] if problems else "a recording lists no readable frame")
    return got


MAX_PHOTONS_REL_SE = 0.5  # a photon count less certain than this (relative standard error) is not stated


def _light(frames, dark, black: float, k: int) -> dict:
    """The recording's signal (DN) and signal-to-noise ratio in the kernel window around its peak
    (``doefab.lab.framechecks.measure_psf``, summed over channels) and its detected photons: per channel the
    window's signal over the conversion gain that the frames' photon transfer gives, with its relative standard
    error (``measure.photon_transfer``; None with one frame, when the fit finds no shot noise, or when the error
    exceeds ``MAX_PHOTONS_REL_SE``)."""
    from doefab.lab.framechecks import measure_psf

    got = measure_psf(frames, dark, black, k)
    photons, var = 0.0, 0.0
    for c in range(len(got.total)):
        s = got.signal[got.window] if got.signal.ndim == 2 else got.signal[got.window][..., c]
        v = None if frames.var is None else (frames.var[got.window] if frames.var.ndim == 2
                                              else frames.var[got.window][..., c])
        fit = None if v is None else photon_transfer(s, v, frames.n)
        if fit is None or photons is None:
            photons = None
            continue
        n_c = got.total[c] / fit[0]
        photons, var = photons + n_c, var + (n_c * fit[1] / fit[0]) ** 2  # each channel's gain fitted alone
    rel = math.sqrt(var) / photons if photons else None
    if rel is not None and rel > MAX_PHOTONS_REL_SE:  # the photon transfer too poorly determined to count
        photons = rel = None
    noise = math.sqrt(sum((t / max(q, 1e-300)) ** 2 for t, q in zip(got.total, got.kernel_snr)))
    noiseless = noise <= 1e-100 * max(abs(float(sum(got.total))), 1.0)  # identical frames (a simulation)
    return {"signal": got.signal, "signal_dn": float(sum(got.total)), "photons": photons, "photons_rel_se": rel,
            "snr": math.inf if noiseless else float(sum(got.total)) / noise,
            "peak_snr": math.inf if noiseless else float(min(got.peak_snr)), "noise": got.noise}


def _require_window_inside(nominal: np.ndarray, chief, shape, what: str, most: float = 1e-3) -> None:
    """Refuse a recording whose K × K window round its chief ray reaches past the frame's edge where the design
    puts more than ``most`` of its light: the window's missing pixels would be read as dark and the rest rescaled
    to the half's share, a wrong PSF."""
    k = nominal.shape[-1]
    rows, cols = (np.arange(k) - k // 2 + int(np.rint(c)) for c in chief)
    inside = ((rows >= 0) & (rows < shape[0]))[:, None] & ((cols >= 0) & (cols < shape[1]))[None, :]
    lost = float(nominal[~inside].sum() / nominal.sum())
    if lost > most:
        raise DoefabError(f"{what}: the {k}×{k}-px PSF window round the chief ray (row {chief[0]:.1f}, column "
                          f"{chief[1]:.1f}) reaches past the {shape[0]}×{shape[1]}-px frame, where {lost:.1%} of the "
                          f"design's light falls: centre the point source in the frame, or record a larger window "
                          f"(2K × 2K leaves room for its offset)")


def calibrate_recording(r, grid: PSFGrid, nominal: dict, fmt: str, black: float, wide: dict | None = None) -> dict:
    """One recording registered, resampled and normalised: {(plane, band): PSF} of its half, the chief ray's
    position and shift from the frame's centre pixel (rows, columns), and its light (:func:`_light`).
    ``nominal``: the nominal PSFs ({half: (planes, bands, K, K)}); ``wide``: the same over the registration's
    wider window (:func:`registration_size`; None: the kernel's, which lacks the tails beyond it)."""
    half = PAIR_HALF[r.half]
    keys = [(z, b, c) for (h, z, b), (rr, c) in grid.entries.items() if rr is r and h == r.half]
    wide = nominal if wide is None else wide
    refs = [nominal[half][grid.planes.index(z), grid.bands.index(b)] for z, b, _ in keys]
    k = refs[0].shape[-1]
    wide_refs = [wide[half][grid.planes.index(z), grid.bands.index(b)] for z, b, _ in keys]
    from doefab.lab.framechecks import frame_black

    frames = _read(r.frames, fmt)
    light = _light(frames, _read(r.dark, fmt) if r.dark else None, frame_black(black, r.frames, fmt), k)
    signal = light.pop("signal")
    chans = [signal if c is None else signal[..., c] for _, _, c in keys]
    chief = register(np.sum(chans, axis=0), np.sum(wide_refs, axis=0), kernel=k)
    what = f"{r.name} ({r.frames[0]})"
    _require_window_inside(np.sum(refs, axis=0), chief, signal.shape[:2], what)
    psfs = {(z, b): normalise(extract(ch, chief, k), float(ref.sum()), what)
            for (z, b, _), ch, ref in zip(keys, chans, refs)}
    centre = np.array(signal.shape[:2]) // 2
    other = "uncoded" if half == "coded" else "coded"
    other_wide = [wide[other][grid.planes.index(z), grid.bands.index(b)] for z, b, _ in keys]
    fits = template_fits(chans, wide_refs, other_wide, k)
    return {"psfs": psfs, "chief_px": chief.tolist(), "shift_px": (chief - centre).tolist(), "frames": frames.n,
            "darks": len(r.dark), "template_fit": fits, **light}


def _wall_view(paths, dark, fmt: str, black: float) -> np.ndarray:
    from doefab.lab.framechecks import frame_black

    s = _read(paths, fmt).mean - (_read(dark, fmt).mean if dark else frame_black(black, paths, fmt))
    return s if s.ndim == 2 else s.sum(axis=-1)  # colour walls: the channels' sum (the ratio is per photodiode)


def _wall_pair_problems(rec: Recordings, by_half: dict, views: dict) -> None:
    """Refuse wall pairs whose two halves' frames differ in size: the ratios are per sensor column."""
    shapes = {h: v[0].shape for h, v in views.items()}
    if shapes["plain"] != shapes["coded"]:
        p, c = by_half["plain"], by_half["coded"]
        raise DoefabError(f"{rec.path}: {p.name} (half = 'plain' open, {Path(p.plain_view[0]).name}) is "
                          f"{shapes['plain'][1]}×{shapes['plain'][0]} px but {c.name} (half = 'coded' open, "
                          f"{Path(c.plain_view[0]).name}) is {shapes['coded'][1]}×{shapes['coded'][0]} px: the "
                          f"crosstalk is per sensor column, so record both walls at one frame size and position")


def measure_walls(rec: Recordings) -> dict | None:
    """Per-column crosstalk from the ``[[wall]]`` pairs (None without any): both halves needed, one pair each."""
    if not rec.wall:
        return None
    by_half = {}
    for w in rec.wall:
        if w.half in by_half:
            raise DoefabError(f"{rec.path}: {w.name} and {by_half[w.half].name} both record the {w.half} half open: "
                              f"list all frames of one half in one [[wall]]")
        by_half[w.half] = w
    if len(by_half) != 2:
        miss = ({"coded", "plain"} - set(by_half)).pop()
        raise DoefabError(f"{rec.path}: the crosstalk needs a white-wall pair with each half open; there is none with "
                          f"half = {miss!r}: add a [[wall]] with half = {miss!r} (the other half blocked)")
    views = {h: (_wall_view(w.plain_view, w.dark, rec.pixel_format, rec.black_level),
                 _wall_view(w.coded_view, w.dark, rec.pixel_format, rec.black_level)) for h, w in by_half.items()}
    for h, (lv, cv) in views.items():
        total = lv + cv
        dark = ~np.isfinite(total) | (total <= 0)
        if dark.any():
            w = by_half[h]
            raise DoefabError(f"{rec.path}: {w.name} (half = {h!r} open): {int(dark.sum())} of {dark.size} pixels get "
                              f"no light once the dark is subtracted (both views summed, first "
                              f"{Path(w.coded_view[0]).name}); the ratios need every pixel lit: expose the white "
                              f"wall longer (about half full scale) and check that the dark frames are the wall's")
    _wall_pair_problems(rec, by_half, views)
    a, b, sa, sb = wall_ratios(views["plain"], views["coded"])
    for h, ratio, name in (("plain", a, "α_l→r"), ("coded", b, "α_r→l")):
        if float(np.median(ratio)) > 0.5:  # most of the open half's light in the other view
            w = by_half[h]
            raise DoefabError(f"{rec.path}: {w.name} (half = {h!r} open) puts most of its light in the view its half "
                              f"does not reach ({name} {float(np.median(ratio)):.3f} in the median column): its "
                              f"coded_view and plain_view appear swapped ({Path(w.coded_view[0]).name}, "
                              f"{Path(w.plain_view[0]).name}); the coded view is the right (DOE) one")
    # the check crosstalk.json's writer makes, before the PSF work rather than after it
    check_pair(a, b, f"{rec.path}: the [[wall]] pairs' alpha_lr, alpha_rl")
    return {"alpha_lr": a, "alpha_rl": b, "alpha_lr_se": sa, "alpha_rl_se": sb,
            "rows": int(views["plain"][0].shape[0])}


def _design_of(rec: Recordings):
    from doefab.design.design import Design

    if rec.design is None:
        raise DoefabError(f"{rec.path} names no design: set design = \"path/to/design\" in it, or pass --design DIR "
                          f"(the design folder or mask set the part was made from)")
    d = Design.load(rec.design)
    return d, d.kernel_size


@dataclass
class Calibration:
    """What the recordings gave, before anything is written: the calibrated ``pair`` (with its provenance), the
    design's ``nominal`` PSFs on the same grid ({half: array}), per recording a summary ``rows`` (shift, frames,
    signal, photons, SNR), the crosstalk ``walls`` (per-column arrays and rows; None without ``[[wall]]``) and
    ``warnings`` (:func:`view_warnings`)."""

    pair: object
    nominal: dict
    rows: list
    walls: dict | None
    warnings: tuple = ()


def measure_recordings(recordings: Recordings, progress: bool = False) -> Calibration:
    """Check ``recordings`` (every frame, :func:`check_recordings`; the grid, :func:`psf_grid`; the wall pairs)
    and calibrate them; nothing is written.

    Normalisation: each half's PSF over the design's kernel sums to the *nominal* half's sum over that kernel —
    a recording cannot know the absolute energy (exposure, source power and transmission are unknown), so the
    share of the light is the model's."""
    import torch

    from doefab.fabrication.levels import levels_sha256
    from doefab.optics.psf import PSFPair

    design, kernel = _design_of(recordings)
    check_recordings(recordings, design.wavelengths, design.depths, kernel)
    grid = psf_grid(recordings, design.wavelengths, design.depths)
    walls = measure_walls(recordings)
    wide = nominal_psfs(design, grid, registration_size(design, grid, kernel))  # the registration's reference
    c = (wide["coded"].shape[-1] - kernel) // 2
    nominal = {h: np.ascontiguousarray(v[..., c:c + kernel, c:c + kernel]) for h, v in wide.items()}
    measured = {h: np.zeros_like(v) for h, v in nominal.items()}
    rows = []
    for r in recordings.psf:
        m = calibrate_recording(r, grid, nominal, recordings.pixel_format, recordings.black_level, wide)
        for (z, b), psf in m.pop("psfs").items():
            measured[PAIR_HALF[r.half]][grid.planes.index(z), grid.bands.index(b)] = psf
        rows.append({"recording": r.name, "half": r.half, "depth_m": r.depth_m, "channels": r.channels,
                     "wavelength_m": r.wavelength_m, "exposure_s": r.exposure_s, **m})
        if progress:
            print(f"[calibrate] {r.name}: shift {m['shift_px'][0]:+.2f}, {m['shift_px'][1]:+.2f} px (rows, columns)",
                  flush=True)
    prov = {"source": "calibrate", "levels_sha256": levels_sha256(design.levels),
            "recordings_sha256": recordings_sha256(recordings), "shifts_px": [row["shift_px"] for row in rows],
            "shift_axes": "[rows down, columns right]: sensor pixels from each [[psf]] frame's centre pixel "
                          "(H//2, W//2) to the chief ray, in the recordings file's order",
            "design": str(recordings.design)}
    pair = PSFPair(torch.from_numpy(measured["coded"].astype(np.float32)),
                   torch.from_numpy(measured["uncoded"].astype(np.float32)),
                   tuple(design.wavelengths[b] for b in grid.bands), tuple(design.depths[z] for z in grid.planes),
                   design.camera.sensor_pitch, provenance=prov)
    return Calibration(pair, nominal, rows, walls, tuple(view_warnings(rows)))


def write_calibration(cal: Calibration, out_dir) -> dict:
    """Write ``psf_pair.npz``, ``crosstalk.json`` (with wall pairs) and ``calibration.html`` into ``out_dir`` (each
    atomically); returns a summary: the files, per recording its shift, frames, signal (DN), photons and SNR, the
    provenance and the crosstalk's column means."""
    from doefab.lab.calreport import write_report

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prov = cal.pair.provenance
    files = [cal.pair.save(out / "psf_pair.npz")]
    if cal.walls is not None:
        from doefab.imaging.crosstalk import save_crosstalk

        w = cal.walls
        files.append(save_crosstalk(out / "crosstalk.json", w["alpha_lr"], w["alpha_rl"], w["alpha_lr_se"],
                                    w["alpha_rl_se"], {"rows": w["rows"], "source": "calibrate",
                                                       "recordings_sha256": prov["recordings_sha256"]}))
    files.append(write_report(out / "calibration.html", cal.pair, cal.nominal, cal.rows, cal.walls, prov,
                              cal.warnings))
    summary = {"files": [str(f) for f in files], "recordings": cal.rows, "provenance": prov,
               "warnings": list(cal.warnings)}
    if cal.walls is not None:
        summary["crosstalk"] = {k: float(np.mean(cal.walls[k])) for k in ("alpha_lr", "alpha_rl")}
    return summary


def calibrate(recordings: Recordings, out_dir, progress: bool = False) -> dict:
    """Calibrate the part and camera from ``recordings`` (:func:`doefab.lab.recordings.load_recordings`;
    :func:`measure_recordings`: every check before any work) and write ``psf_pair.npz``, ``crosstalk.json``
    (with ``[[wall]]`` pairs) and ``calibration.html`` into ``out_dir`` (:func:`write_calibration`), nothing when
    a check fails. Returns :func:`write_calibration`'s summary."""
    return write_calibration(measure_recordings(recordings, progress), out_dir)
