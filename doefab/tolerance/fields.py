"""A part's relief transmittance at each wavelength, built within a memory budget.

The judge builds the relief of a window of the die (``relief.ReliefModel``: the pattern areas of each cell, turned
by the mount rotation) and its transmittance at every wavelength. For the shipped designs that is a few hundred
megabytes and is built at once. A larger design grid (a camera with more DOE pixels across its aperture, a finer
tolerance grid) times many wavelengths would need tens of gigabytes at once: a 31-band grating of 2188 DOE pixels
across, on the tolerance stage's twofold grid, took 11 GB before its first PSF. Above ``FIELD_BYTES`` the
transmittance is therefore computed one wavelength at a time from the pattern areas, which are kept instead
(``PerWavelength``), and the mount rotation turns the pattern areas a few at a time (``ROTATE_BYTES``). The
values are the same to float32 rounding (the matrix products and FFTs run in other batch shapes).
"""

from __future__ import annotations

import math

import numpy as np
import torch

__all__ = ["relief_fields", "PerWavelength", "part_bytes", "builds_at_once", "part_size", "parts_that_fit",
           "require_memory", "FIELD_BYTES", "ROTATE_BYTES"]

FIELD_BYTES = 2 * 2**30  # bytes of complex64 transmittance built at once; above it, one wavelength at a time
ROTATE_BYTES = 256 * 2**20  # bytes of pattern areas the mount rotation turns at once (its FFTs need ~5× that)


# a judged part's peak memory per grid cell: a fixed share (one transmittance, the propagation's canvases), one per
# pattern area (the die's and the turned window's), and each wavelength's transmittance twice (the relief's and what
# it is built from) when built at once (below FIELD_BYTES); built one at a time, ONE_AT_A_TIME_BYTES in its place:
# a few wavelengths' transmittances and the heap's growth from part to part, whose freed blocks of hundreds of
# megabytes the next blocks of other sizes do not fit (freed memory is kept, ``doefab.keep_freed_memory``); and what
# the process holds besides (torch, networks)
CELL_BYTES, PATTERN_BYTES, PROCESS_BYTES = 112, 6, 2**29
BAND_BYTES, ONE_AT_A_TIME_BYTES = 16, 240


def part_bytes(doe_pixels: int, supersample: int, n_masks: int, n_wavelengths: int = 1) -> int:
    """Bytes one process needs to judge one part of a design of ``doe_pixels`` DOE pixels across, ``n_masks``
    binary masks and ``n_wavelengths`` bands on the ``supersample``× grid, as a ``doefab`` command runs it (freed
    memory kept for reuse, ``doefab.keep_freed_memory``): (S·N)² cells × (112 + 6·2^M + 16·W) bytes + 0.5 GiB, the
    16·W while the W transmittances are built at once (8·W·cells ≤ ``FIELD_BYTES``), 240 bytes in its place when
    they are built one at a time. Measured peaks (2 threads, both halves of a turned part): 16 levels, 3 bands,
    N = 2000, S = 1, 2, 4: 1.08, 3.21, 11.0 GB (this gives 1.56, 4.63, 16.9); 2 levels, 3 bands, N = 2188, S = 1,
    2: 0.92, 2.15 GB (1.36, 3.83); 16 levels, 31 bands, N = 2188, S = 2: 3.6 GB for one part, 8.0 GB for its whole
    ``doefab run --quick`` (9.1, one band at a time); and whole studies of 16 levels, 31 bands, N = 634:
    ``doefab tolerance --samples 1`` on the 4× and 8× grids 4.1 and 6.1-6.5 GB (5.1, 12.1), the tolerance stage of
    ``doefab run --quick`` (through the networks) on the 8× grid 8.6-11.8 GB from run to run (12.1: within 3 % of
    the highest run). It errs on the high side elsewhere. Where the bands go one at a time the estimate drops (a
    31-band design of 2942 DOE pixels on the design grid: 6.6 GB, of 2943: 4.4 GB); the grid steps of a study
    (×4 cells each) stay in order.

    Example: ``part_bytes(2188, 2, 4, 31) / 1e9`` → 9.1 (GB).
    """
    cells = (int(doe_pixels) * int(supersample)) ** 2
    at_once = builds_at_once(n_wavelengths, cells)
    per = CELL_BYTES + PATTERN_BYTES * (1 << int(n_masks)) + (BAND_BYTES * int(n_wavelengths) if at_once
                                                              else ONE_AT_A_TIME_BYTES)
    return cells * per + PROCESS_BYTES


def builds_at_once(n_wavelengths: int, cells: int) -> bool:
    """Whether the transmittance of ``n_wavelengths`` wavelengths over ``cells`` grid cells (complex64, 8 bytes
    each) is built at once (within ``FIELD_BYTES``) rather than one wavelength at a time (``PerWavelength``)."""
    return 8 * int(n_wavelengths) * int(cells) <= FIELD_BYTES


def parts_that_fit(size: tuple, supersample: int, available: int | None = None) -> int | None:
    """How many parts (``part_bytes`` each) fit at once in ``available`` bytes (None: what this machine has now,
    ``doefab._memory.available_bytes``); None where that is unknown. ``size``: (DOE pixels across, masks, bands)."""
    from doefab._memory import available_bytes

    available = available_bytes() if available is None else available
    return None if available is None else int(available // part_bytes(size[0], supersample, *size[1:]))


def require_memory(size: tuple, grid: int, grids: tuple, bounds: dict | None = None, parts: int = 1,
                   available: int | None = None) -> None:
    """Refuse, before any part is judged, a study whose ``parts`` parts at once (one per process) on the ``grid``×
    grid do not fit in the memory available (``parts_that_fit``; ``size``: (DOE pixels across, masks, bands)); the
    message names the largest of the grid study's ``grids`` (``grid.GRIDS``) that fits and, from its ``bounds``
    ({grid: the task metric's error bound there}), what that grid costs in accuracy."""
    from doefab._memory import SHARE_ENV, available_bytes, memory_share
    from doefab.errors import DoefabError

    have = available_bytes() if available is None else available  # read once: the message states what was judged
    if have is None or parts_that_fit(size, grid, have) >= parts:
        return
    need = parts * part_bytes(size[0], grid, *size[1:])
    fits = [s for s in sorted(grids, reverse=True) if s < grid and parts_that_fit(size, s, have) >= parts]
    what = f"{parts} parts at once" if parts > 1 else "one part"
    where = f"on a machine with {math.ceil(need / 1e9)} GB free" + (", or with fewer workers" if parts > 1 else "")
    if memory_share() is not None:  # a scene of doefab run --jobs, or the user's own limit
        where += (f" ({SHARE_ENV} limits this process: doefab run --jobs gives each scene side by side its part of "
                  f"the memory; fewer at once, e.g. --jobs 1, give each more)")
    if not fits:
        fix = f"run it {where}"
    else:
        b = {int(k): v for k, v in (bounds or {}).items()}.get(fits[0])
        cost = "" if b is None else f"; the grid study bounds the task metric's error there by {b:.2g}"
        fix = (f"fix the grid with the scene's tolerance.supersample = {fits[0]} (doefab tolerance --grid "
               f"{fits[0]}){cost}, or run it {where}")
    raise DoefabError(f"{what} of this design ({size[0]} DOE pixels across, {1 << size[1]} levels, {size[2]} bands) "
                      f"on the {grid}× grid need{'s' if parts == 1 else ''} about {need / 1e9:.1f} GB and "
                      f"{have / 1e9:.1f} GB is available: {fix}")


def part_size(design, n_masks: int) -> tuple:
    """(DOE pixels across, masks, bands) of ``design``: what ``part_bytes`` takes."""
    return design.camera.doe_pixels, int(n_masks), len(design.wavelengths)


class PerWavelength:
    """``self[i]``: wavelength i's transmittance [cells] complex64, computed when asked from the pattern areas
    ``hist`` [2^M, cells], the pattern heights (m), each wavelength's phase per metre of relief and, with
    roughness, its height field and unresolved rms (m), as ``relief_fields`` computes it for all at once."""

    def __init__(self, hist: torch.Tensor, heights: np.ndarray, phases, rough=None):
        self.hist, self.heights, self.phases, self.rough = hist, heights, list(phases), rough

    def __getitem__(self, i: int) -> torch.Tensor:
        from doefab.tolerance.relief import transmittance

        c = self.phases[i]
        f = transmittance(self.hist, self.heights, [c])[0]
        return f if self.rough is None else f * _roughness(c, self.rough)

    def to(self, device) -> PerWavelength:
        """Itself: each wavelength moves to the device when the judge asks for it."""
        return self


def relief_fields(relief, me, heights: np.ndarray, phases, rows, cols, rough=None):
    """The transmittance [W, cells] of the die window ``rows`` × ``cols`` (grid cells) of ``relief`` (a
    ``ReliefModel``) with mask errors ``me`` (``MaskErrors``; its ``mount_rotation`` in radians), at W wavelengths
    of ``phases`` (rad per metre of relief each), relative to the plain glass: a complex64 tensor, or, above
    ``FIELD_BYTES``, a ``PerWavelength`` that computes one row at a time. With fewer than half as many wavelengths
    as patterns and a mount rotation, the transmittance itself is turned, whole (it is then smaller than the pattern
    areas it is made from). ``rough``: (height field [cells] (m), unresolved rms (m)) of the etch roughness, or
    None.

    Example: ``relief_fields(judge.relief, judge.mask_errors(err), heights, phases, (0, 64), (0, 64))``.
    """
    from doefab.tolerance.relief import rotate_fields, transmittance

    (r0, r1), (c0, c_end) = rows, cols
    th = float(me.mount_rotation)
    n_w, cells = len(phases), (r1 - r0) * (c_end - c0)
    if th == 0.0:
        hist = relief.die_histogram(me, (r0, r1), (c0, c_end))
    else:
        big, bigc = relief.rotation_window(th, (r0, r1), (c0, c_end))
        die = relief.die_histogram(me, big, bigc)
        if 2 * n_w < die.shape[0]:  # fewer wavelengths than patterns: turn the transmittance
            fields = rotate_fields(transmittance(die, heights, phases), th, (r0, r1), (c0, c_end), big, bigc,
                                   relief.n, torch.ones(n_w, dtype=torch.complex64))
            return _roughen(fields, phases, rough)
        hist = _rotate_patterns(die, th, (r0, r1), (c0, c_end), big, bigc, relief.n)
    if not builds_at_once(n_w, cells):
        return PerWavelength(hist, heights, phases, rough)
    return _roughen(transmittance(hist, heights, phases), phases, rough)


def _rotate_patterns(die: torch.Tensor, th: float, rows, cols, big, bigc, n: int) -> torch.Tensor:
    """The pattern areas ``die`` [2^M, big × bigc cells] turned by ``th`` onto ``rows`` × ``cols``, at most
    ``ROTATE_BYTES`` of them at a time (outside the die window: the first pattern, unetched glass)."""
    from doefab.tolerance.relief import rotate_fields

    plain = torch.zeros(die.shape[0])
    plain[0] = 1.0
    per = max(1, int(ROTATE_BYTES // max(1, die[0].numel() * die.element_size())))
    if per >= die.shape[0]:
        return rotate_fields(die, th, rows, cols, big, bigc, n, plain)
    return torch.cat([rotate_fields(die[a:a + per], th, rows, cols, big, bigc, n, plain[a:a + per])
                      for a in range(0, die.shape[0], per)])


def _roughen(fields: torch.Tensor, phases, rough) -> torch.Tensor:
    """``fields`` [W, cells] times each wavelength's roughness transmittance (in place), if any."""
    if rough is None:
        return fields
    for i, c in enumerate(phases):
        fields[i] *= _roughness(c, rough)
    return fields


def _roughness(c: float, rough) -> torch.Tensor:
    """[cells] complex64: the etch roughness's transmittance at phase ``c`` per metre of relief, from ``rough`` =
    (height field [cells] (m), unresolved rms (m)): the resolved heights' phase, the unresolved rms's loss."""
    r, resid = rough
    return torch.polar(torch.full_like(r, math.exp(-0.5 * (c * resid) ** 2)), c * r)
