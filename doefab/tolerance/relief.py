"""The relief of a fabricated part as its masks made it, sampled for wave optics by exact areas.

A DOE of L = 2^M levels is etched by M binary masks: mask m removes 2^m·d where it is open (bit m of
L − 1 − level). At any point of a part the relief is therefore one of 2^M heights, set by which masks etched
there (its *pattern*): fabrication errors move, grow and shrink each mask's etched region, they never make
heights in between. A simulation cell crossed by an edge holds two or more heights side by side, and what it
sends into the far field is the area-weighted mean of their *complex transmittances* (the flat-tile
approximation, exact as the cell shrinks; ``benchmarks/tolerance_grid.py`` measures it against finer grids).
Averaging heights instead would turn a sliver of a 2π·15/16 step into a cell of phase π.

:class:`ReliefModel` gives, for every cell, the exact area fraction of every pattern, ``H [cells, 2^M]``:

1. the die, on the design grid refined ``s``×: each mask translated by its overlay (a mask rotation is a
   translation that varies across the die and is applied per tile), its etched region grown or shrunk by the
   edge bias (square-cornered: L∞ dilation or erosion of the union of its pixels), then, per cell, the exact
   areas of the rectangles the masks' edges cut it into;
2. the mount rotation: the die turned by θ about its centre against the sensor-aligned grid; each cell takes
   the four die cells around its source point with the area weights of a local translation.

A decenter of the die never touches the relief (``doefab.tolerance.mounted`` moves the split line and the lens
instead). With no error every cell holds one pattern and ``H`` is the level map exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft
import torch

from doefab.errors import DoefabError

__all__ = ["ReliefModel", "MaskErrors", "pattern_heights", "transmittance", "mean_height", "ZONE_REACH",
           "corner_bias", "rotate_fields", "plain_columns"]

# A mask's edges within one cell, along one axis: the boundary nearest the cell's leading edge at ρ ∈ (−½, ½],
# the next at ρ + 1, each widened by the bias β (|β| ≤ ½) into [b − β, b + β]. Zone z of the five these four
# breakpoints make is reached by the block columns (relative to the one right of ρ) listed here.
ZONE_REACH = ((-1,), (-1, 0), (0,), (0, 1), (1,))
MAX_TILE_ERROR = 0.05  # cells: a mask rotation is applied per tile, as the translation at the tile's centre
MIN_GROUP = 20000  # cells: smaller groups of alike cells are merged (fewer, larger array operations)


@dataclass(frozen=True)
class MaskErrors:
    """Where each mask landed on the die and how its edges moved (SI units).

    shifts: per mask (dx, dy) metres, x right, y up (relative to the chrome layer, chain composed).
    rotations: per mask, radians about the die centre.  bias: per mask, metres each edge moved outward
    (> 0 etched regions grow).  mount_rotation: radians, the whole die against the sensor's axes.
    """

    shifts: tuple
    rotations: tuple
    bias: tuple
    mount_rotation: float = 0.0


def _zone_lut(grow: bool) -> torch.Tensor:
    """[512, 25] bool: etched state of zone (zy·5 + zx) of a cell whose 3×3 source block has code ``c``
    (bit 3·(dy+1) + (dx+1)). Growth: etched if any reached source pixel is (L∞ dilation of the union);
    shrinkage: if all are (erosion)."""
    bits = (np.arange(512)[:, None] >> np.arange(9)[None, :]) & 1
    out = np.zeros((512, 25), bool)
    for zy, ry in enumerate(ZONE_REACH):
        for zx, rx in enumerate(ZONE_REACH):
            sel = bits[:, [3 * (dy + 1) + (dx + 1) for dy in ry for dx in rx]]
            out[:, zy * 5 + zx] = sel.any(axis=1) if grow else sel.all(axis=1)
    return torch.from_numpy(out)


_LUTS = {True: _zone_lut(True), False: _zone_lut(False)}


def _varies() -> tuple[torch.Tensor, torch.Tensor]:
    """[512] bool each: whether a 3×3 block's values change along x (within a row) or along y (within a column).
    A cell whose masks' blocks do not change along y has the same pattern in every y-zone, and so on."""
    bits = ((np.arange(512)[:, None] >> np.arange(9)[None, :]) & 1).reshape(512, 3, 3)
    along_x = (bits != bits[:, :, :1]).any(axis=(1, 2))
    along_y = (bits != bits[:, :1, :]).any(axis=(1, 2))
    return torch.from_numpy(along_x), torch.from_numpy(along_y)


_VARIES_X, _VARIES_Y = _varies()


def _block_codes(plane: np.ndarray) -> torch.Tensor:
    """9-bit code of each cell's 3×3 neighbourhood (``plane`` padded by one unetched cell)."""
    p = np.pad(plane.astype(np.int32), 1)
    r, c = plane.shape
    code = np.zeros((r, c), np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            code |= p[1 + dy:1 + dy + r, 1 + dx:1 + dx + c] << (3 * (dy + 1) + (dx + 1))
    return torch.from_numpy(code.astype(np.int16))


def _axis_zones(shift_cells: float, bias_cells: float) -> tuple[int, np.ndarray]:
    """(offset o, the 4 breakpoints) of one mask along one axis: the cell at index j reads its 3×3 source block
    around j − o; breakpoints are cell-local positions in [0, 1] order."""
    n = math.floor(shift_cells)
    f = shift_cells - n
    i0 = 0 if f <= 0.5 else -1
    rho = f + i0
    b = abs(bias_cells)
    return n - i0, np.array([rho - b, rho + b, rho + 1 - b, rho + 1 + b])


def _intervals(breaks: list[np.ndarray], masks: list[int], n_masks: int) -> list[tuple[float, tuple]]:
    """[(width, zone of every mask)] of the pieces of [0, 1] that the breakpoints of ``masks`` cut (empty ones
    left out); the other masks have no edge along this axis and read zone 2 (the cell's own source pixel)."""
    cuts = sorted({0.0, 1.0, *(float(min(max(v, 0.0), 1.0)) for bp in breaks for v in bp)})
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b - a > 1e-12:
            t = 0.5 * (a + b)
            z = [2] * n_masks
            for m, bp in zip(masks, breaks):
                z[m] = int(np.sum(bp < t))
            out.append((b - a, tuple(z)))
    return out


def corner_bias(plane: np.ndarray, radius_px: float) -> float:
    """Edge bias (pixels, < 0 shrinks) that removes the area corner rounding of radius ``radius_px`` takes:
    (1 − π/4) r² off each convex corner of the etched region, added at each concave one, spread over its
    perimeter. Corner rounding itself is a second-order change of a few 1e-4 of a cell per corner."""
    if radius_px <= 0 or not plane.any():
        return 0.0
    p = np.pad(plane.astype(np.int8), 1)
    quad = p[:-1, :-1] + p[:-1, 1:] + p[1:, :-1] + p[1:, 1:]  # etched pixels around each grid vertex
    diag = (p[:-1, :-1] == p[1:, 1:]) & (p[:-1, 1:] == p[1:, :-1]) & (quad == 2)
    convex = int((quad == 1).sum() + 2 * diag.sum())
    concave = int((quad == 3).sum())
    perimeter = int(np.abs(np.diff(p, axis=0)).sum() + np.abs(np.diff(p, axis=1)).sum())
    return -(1 - math.pi / 4) * radius_px ** 2 * (convex - concave) / max(perimeter, 1)


class ReliefModel:
    """Pattern areas of a part on the design grid refined ``supersample``× (see the module docstring).

    Args:
        planes: (M, N, N) bool, mask m's etched pixels (bit planes of the level map).
        pitch: design (DOE) pixel pitch, metres.  supersample: cells per design pixel and axis.
    """

    def __init__(self, planes: np.ndarray, pitch: float, supersample: int = 1):
        planes = np.asarray(planes, bool)
        if planes.ndim != 3 or planes.shape[1] != planes.shape[2]:
            raise DoefabError(f"mask planes must be (M, N, N), got {planes.shape}")
        if not isinstance(supersample, int) or not 1 <= supersample <= 16:
            raise DoefabError(f"supersample must be an integer 1..16, got {supersample!r}")
        self.n_masks, self.design_px = planes.shape[0], planes.shape[1]
        self.s, self.pitch = supersample, float(pitch)
        self.cell = self.pitch / supersample
        self.n = self.design_px * supersample
        self.planes = planes
        self._fine = [np.kron(p, np.ones((supersample, supersample), bool)) if supersample > 1 else p
                      for p in planes]
        self._codes: dict = {}

    @property
    def n_patterns(self) -> int:
        return 1 << self.n_masks

    def _code_map(self, m: int, grow_cells: int, pad: int) -> torch.Tensor:
        """Padded 3×3-block code map of mask m after a whole-cell L∞ growth (> 0) or shrinkage (< 0)."""
        key = (m, grow_cells, pad)
        if key not in self._codes:
            plane = self._fine[m]
            if grow_cells:
                from scipy import ndimage

                size = 2 * abs(grow_cells) + 1
                op = ndimage.maximum_filter if grow_cells > 0 else ndimage.minimum_filter
                plane = op(plane, size=size, mode="constant", cval=0)
            self._codes[key] = _block_codes(np.pad(plane, pad))
            if len(self._codes) > 4 * self.n_masks:  # one part's odd growth must not pin memory
                self._codes.pop(next(iter(self._codes)))
        return self._codes[key]

    def die_histogram(self, err: MaskErrors, rows: tuple[int, int], cols: tuple[int, int]) -> torch.Tensor:
        """[2^M, rows × cols] pattern areas (fractions of a cell) of the die cells in the window (stage 1)."""
        self._check(err)
        r0, r1 = rows
        c0, c1 = cols
        h = torch.zeros(self.n_patterns, (r1 - r0) * (c1 - c0))
        rot = max((abs(float(t)) for t in err.rotations), default=0.0)
        half = self.n / 2
        tile = int(min(max(MAX_TILE_ERROR / max(rot, 1e-30), 16), self.n))
        for tr in range(r0, r1, tile):
            for tc in range(c0, c1, tile):
                rr, cc = (tr, min(tr + tile, r1)), (tc, min(tc + tile, c1))
                centre = ((0.5 * (cc[0] + cc[1]) - half) * self.cell, (half - 0.5 * (rr[0] + rr[1])) * self.cell)
                sub = self._tile_histogram(err, rr, cc, centre)
                if (rr, cc) == ((r0, r1), (c0, c1)):
                    return sub
                idx = (torch.arange(rr[0] - r0, rr[1] - r0)[:, None] * (c1 - c0)
                       + torch.arange(cc[0] - c0, cc[1] - c0)[None, :]).reshape(-1)
                h[:, idx] = sub
        return h

    def _check(self, err: MaskErrors) -> None:
        for name in ("shifts", "rotations", "bias"):
            if len(getattr(err, name)) != self.n_masks:
                raise DoefabError(f"{name} needs one entry per mask ({self.n_masks})")

    def _mask_zones(self, err: MaskErrors, m: int, rows, cols, centre):
        """(codes of the cells' source blocks, grow?, x breakpoints, y breakpoints) of mask m in a tile."""
        cx, cy = centre
        th = float(err.rotations[m])
        # the rotation about the die centre, as the translation it gives this tile's centre
        dx = float(err.shifts[m][0]) + (math.cos(th) - 1) * cx - math.sin(th) * cy
        dy = float(err.shifts[m][1]) + math.sin(th) * cx + (math.cos(th) - 1) * cy
        b = float(err.bias[m]) / self.cell
        grow = int(round(b))
        frac = b - grow
        ox, bx = _axis_zones(dx / self.cell, frac)
        oy, by = _axis_zones(-dy / self.cell, frac)  # rows grow downward
        pad = 8 * (max(abs(ox), abs(oy)) // 8 + 1)
        code = self._code_map(m, grow, pad)
        (r0, r1), (c0, c1) = rows, cols
        sub = code[pad + r0 - oy:pad + r1 - oy, pad + c0 - ox:pad + c1 - ox].reshape(-1).long()
        return sub, frac >= 0, bx, by

    def _tile_histogram(self, err: MaskErrors, rows, cols, centre) -> torch.Tensor:
        """Stage 1 on one tile. A mask whose source block does not change along y in a cell has the same state
        in all of that cell's y-zones (likewise x), so cells are grouped by which masks change along x and
        along y in them, and a group's cells are cut only by those masks' breakpoints (small groups are
        merged and cut by the union of theirs)."""
        zones = [self._mask_zones(err, m, rows, cols, centre) for m in range(self.n_masks)]
        n = (rows[1] - rows[0]) * (cols[1] - cols[0])
        h = torch.zeros(self.n_patterns, n)
        key = torch.zeros(n, dtype=torch.int32)
        for m, (code, _, _, _) in enumerate(zones):
            key |= (_VARIES_X[code].int() << m) | (_VARIES_Y[code].int() << (self.n_masks + m))
        order = torch.argsort(key)
        keys, counts = torch.unique_consecutive(key[order], return_counts=True)
        groups, small, start = [], [], 0
        for k, cnt in zip(keys.tolist(), counts.tolist()):
            (groups if cnt >= MIN_GROUP else small).append((k, order[start:start + cnt]))
            start += cnt
        if small:
            merged = 0
            for k, _ in small:
                merged |= k
            groups.append((merged, torch.cat([idx for _, idx in small])))
        flat = h.view(-1)
        for k, idx in groups:
            along_x = [m for m in range(self.n_masks) if k >> m & 1]
            along_y = [m for m in range(self.n_masks) if k >> (self.n_masks + m) & 1]
            xs = _intervals([zones[m][2] for m in along_x], along_x, self.n_masks)
            ys = _intervals([zones[m][3] for m in along_y], along_y, self.n_masks)
            codes = [z[0][idx] for z in zones]
            states: dict = {}

            def state(m, zy, zx):
                if (m, zy, zx) not in states:
                    states[m, zy, zx] = _LUTS[zones[m][1]][:, zy * 5 + zx][codes[m]].long() << m
                return states[m, zy, zx]

            for wy, zys in ys:
                for wx, zxs in xs:
                    pattern = state(0, zys[0], zxs[0])
                    for m in range(1, self.n_masks):
                        pattern = pattern + state(m, zys[m], zxs[m])
                    flat.index_add_(0, pattern * n + idx, torch.full((idx.numel(),), wy * wx))
        return h

    def rotation_window(self, theta: float, rows: tuple[int, int], cols: tuple[int, int]) -> tuple:
        """The die window whose cells a rotation by ``theta`` brings into ``rows × cols``."""
        reach = abs(theta) * math.hypot(self.n, self.n) / 2 + 2
        return ((max(0, int(rows[0] - reach)), min(self.n, int(rows[1] + reach) + 1)),
                (max(0, int(cols[0] - reach)), min(self.n, int(cols[1] + reach) + 1)))

    def histogram(self, err: MaskErrors, rows: tuple[int, int] | None = None,
                  cols: tuple[int, int] | None = None) -> torch.Tensor:
        """[2^M, cells] pattern areas of the cells ``rows × cols`` of the sensor-aligned grid centred on the
        die (stage 1, then the mount rotation, stage 2)."""
        rows = rows or (0, self.n)
        cols = cols or (0, self.n)
        th = float(err.mount_rotation)
        if th == 0.0:
            return self.die_histogram(err, rows, cols)
        big, bigc = self.rotation_window(th, rows, cols)
        die = self.die_histogram(err, big, bigc)
        plain = torch.zeros(die.shape[0])
        plain[0] = 1.0
        return rotate_fields(die, th, rows, cols, big, bigc, self.n, plain)


def rotate_fields(die: torch.Tensor, theta: float, rows, cols, big, bigc, n: int, outside) -> torch.Tensor:
    """Stage 2: fields [C, cells of the die window big × bigc] (real or complex) turned by θ about the die
    centre onto the sensor-aligned window rows × cols; ``outside`` [C]: their value beyond the window.

    What a pixelated relief sends into the window is its samples' array factor times one pixel's far field; a
    turned lattice's array factor within the band is that of its samples moved by band-limited interpolation,
    which three shears do exactly (Unser et al. 1995: each shear shifts every row, or column, by a Fourier
    phase ramp). The pattern-area fields and the transmittance are linear in each other, so either may be
    turned (the judge turns whichever has fewer channels). Content the shears push past the band's edge wraps
    to the far edge, never into the window the PSFs use. (Area-weighted resampling instead would attenuate the
    window's light by up to f(1 − f)(2πua)², several per cent at a grating's first order.)
    """
    wr, wc = big[1] - big[0], bigc[1] - bigc[0]
    f = die.reshape(die.shape[0], wr, wc)
    a, b = -math.tan(theta / 2), math.sin(theta)
    c = (n - 1) / 2
    y = c - torch.arange(big[0], big[1], dtype=torch.float64)  # cells from the die centre, y up
    x = torch.arange(bigc[0], bigc[1], dtype=torch.float64) - c
    pad = int(math.ceil(max(abs(a) * float(y.abs().max()), abs(b) * float(x.abs().max())))) + 4
    # each axis is padded on its far side up to a length the FFT factors well (a length with a large prime
    # factor costs several times more; a longer period moves nothing into the window)
    real = not f.is_complex()
    er = scipy.fft.next_fast_len(wr + 2 * pad, real=real) - wr - pad
    ec = scipy.fft.next_fast_len(wc + 2 * pad, real=real) - wc - pad
    out = torch.as_tensor(outside).to(f.dtype).reshape(-1, 1, 1)
    f = torch.nn.functional.pad(f - out, (pad, ec, pad, er)) + out
    yp = torch.cat([y[0] + torch.arange(pad, 0, -1.0), y, y[-1] - torch.arange(1.0, er + 1)])
    xp = torch.cat([x[0] - torch.arange(pad, 0, -1.0), x, x[-1] + torch.arange(1.0, ec + 1)])
    f = _shear(f, a * yp, dim=2)  # each row moves a·y along x
    f = _shear(f, -b * xp, dim=1)  # each column moves b·x up, i.e. −b·x in rows
    f = _shear(f, a * yp, dim=2)
    r0, c0 = rows[0] - big[0] + pad, cols[0] - bigc[0] + pad
    return f[:, r0:r0 + rows[1] - rows[0], c0:c0 + cols[1] - cols[0]].reshape(f.shape[0], -1).contiguous()


def _shear(f: torch.Tensor, shift: torch.Tensor, dim: int) -> torch.Tensor:
    """Move each line of ``f`` [C, H, W] (real or complex) along ``dim`` (1: rows, 2: columns) by ``shift``
    cells (one value per line; content moves toward increasing index) with a Fourier phase ramp; the Nyquist bin
    of an even length is dropped."""
    length = f.shape[dim]
    real = not f.is_complex()
    spec = torch.fft.rfft(f, dim=dim) if real else torch.fft.fft(f, dim=dim)
    k = torch.fft.rfftfreq(length, 1.0 / length) if real else torch.fft.fftfreq(length, 1.0 / length)
    k = k.double()
    nyq = (k.abs() == length / 2) if length % 2 == 0 else torch.zeros_like(k, dtype=torch.bool)
    if dim == 2:
        phase, drop = shift[None, :, None] * k[None, None, :], nyq[None, None, :]
    else:
        phase, drop = k[None, :, None] * shift[None, None, :], nyq[None, :, None]
    ramp = torch.exp(-2j * math.pi * phase / length).to(torch.complex64)
    ramp = torch.where(drop, torch.zeros((), dtype=ramp.dtype), ramp)
    if real:
        return torch.fft.irfft(spec * ramp, n=length, dim=dim)
    return torch.fft.ifft(spec * ramp, dim=dim)


def plain_columns(planes: np.ndarray) -> int:
    """The first design column from which every column is unetched by every mask (the plain half)."""
    any_etch = np.asarray(planes).any(axis=(0, 1))
    idx = np.nonzero(any_etch)[0]
    return int(idx[-1]) + 1 if idx.size else 0


def pattern_heights(n_masks: int, step: float, depth_scale=None) -> np.ndarray:
    """[2^M] heights (metres) of every pattern: (L − 1)·d − Σ_m scale_m·2^m·d over the masks that etched."""
    scale = np.ones(n_masks) if depth_scale is None else np.asarray(depth_scale, np.float64)
    p = np.arange(1 << n_masks)
    etched = ((p[:, None] >> np.arange(n_masks)[None, :]) & 1) * (scale * (1 << np.arange(n_masks)))[None, :]
    return ((1 << n_masks) - 1) * step - step * etched.sum(axis=1)


def transmittance(hist: torch.Tensor, heights: np.ndarray, phases_per_metre) -> torch.Tensor:
    """[W, cells] complex64: the cells' mean complex transmittance exp(i·k·Δn·h) at each of W wavelengths,
    given the pattern areas ``hist`` [2^M, cells] and each wavelength's phase per metre of relief k·Δn."""
    c = np.atleast_1d(np.asarray(phases_per_metre, np.float64))
    ph = np.asarray(heights, np.float64)[None, :] * c[:, None]  # [W, 2^M]
    e = torch.from_numpy(np.concatenate([np.cos(ph), np.sin(ph)], axis=0)).float()
    re_im = e @ hist.float()
    return torch.complex(re_im[:len(c)], re_im[len(c):])


def mean_height(hist: torch.Tensor, heights: np.ndarray) -> torch.Tensor:
    """[cells] float64: the cells' area-weighted mean height (metres)."""
    return torch.from_numpy(np.asarray(heights, np.float64)) @ hist.double()
