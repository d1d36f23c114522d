"""Judge a fabricated and mounted part on its PSF: the design's task metric and the L1 distance to nominal.

``PSFJudge`` is built once per design and simulation grid (per worker). A part's PSF comes from:

- its relief as its masks made it (``relief.ReliefModel``: overlay and mask rotation composed along the mask
  set's alignment chain, edge bias, corner rounding, etch depth per mask, roughness), each cell sending the
  mean complex transmittance of the heights it holds; the mount rotation turns the relief against the sensor;
- its mount (``mounted.MountedPlan``): a decenter moves the split line and the lens, never the relief; an
  axial gap is propagated only when the lens, not the DOE, is the aperture stop;
- dual-pixel crosstalk (``doefab.imaging.crosstalk``, Eq. 29) mixing the plain half's PSF into the coded view,
  unmixed — when the budget says the camera is calibrated — with ratios estimated from simulated noisy
  white-wall captures (Eq. 30–31), so the calibration's own error reaches the result. At PSF level the plain
  half is the nominal one (the part's differs only by relief slivers that cross the split, and it enters
  weighted by the crosstalk ratio); the network judge uses both halves of the part.

The relief is built on the CPU; its transmittance moves to the judge's ``device`` once per part, where the PSFs are
propagated; the PSFs the judge returns and keeps are on the CPU.
"""

from __future__ import annotations

import hashlib
import json
import time
import weakref
from collections import OrderedDict
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch

from doefab._devices import resolve_device, to_device
from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.fabricate import alignment_chain, compose_overlay, refined_camera, roughness_field
from doefab.tolerance.sources import apply_psf_effects, tilt_phase_factor

__all__ = ["PSFJudge", "alignment_chain", "compose_overlay", "psf_source", "planes_among", "DEFAULT_MARGIN"]

DEFAULT_MARGIN = 0.3e-3  # metres of decenter every part shares one sample grid for (the holder allows 0.25 mm)


def psf_source(err: PartErrors | None = None, height=None, doe_is_stop: bool = False) -> str:
    """What a part's PSFs are computed from, as ``PSFJudge.reuse`` keys them: the part's errors that reach its
    pupil (not the sensor's, ``sources.sensor_errors``; not a roughness's parameters when it has none; not an axial
    gap when ``doe_is_stop``: then it moves nothing, ``mounted``), or an explicit height map's digest (metres, on
    the judge's grid).

    Example:
        >>> psf_source(PartErrors())[:5], psf_source(height=np.zeros((2, 2)))[:7]
        ('part ', 'height ')
        >>> psf_source(PartErrors(crosstalk=(0.02, 0.01))) == psf_source(PartErrors())
        True
    """
    from doefab.tolerance.sources import sensor_errors

    if height is not None:
        h = np.ascontiguousarray(np.asarray(height, np.float64))
        return "height " + hashlib.sha256(h.tobytes()).hexdigest() + str(tuple(h.shape))
    if err is None:
        raise DoefabError("psf_source needs a part's errors or a height map: psf_source(PartErrors())")
    off = set(sensor_errors({})) | ({"roughness_corr", "seed"} if err.roughness == 0 else set())
    off |= {"axial_gap"} if doe_is_stop else set()
    return "part " + json.dumps({k: v for k, v in err.to_json().items() if k not in off}, sort_keys=True, default=str)


def planes_among(planes, among) -> list[int] | None:
    """The index of each of ``planes`` (metres) in ``among`` when all are there (equal to 1e-12), else None.

    Example:
        >>> planes_among([1.0, 2.0], [1.0, 1.5, 2.0]), planes_among([1.0, 1.2], [1.0, 2.0])
        ([0, 2], None)
    """
    among = np.asarray(among, np.float64)
    idx = [np.flatnonzero(np.isclose(among, z, rtol=1e-12, atol=0.0)) for z in planes]
    return None if any(len(i) != 1 for i in idx) else [int(i[0]) for i in idx]


class PSFJudge:
    """PSF-level judge of one design folder (``design.json`` + ``levels.npy``, or a ``Design``) on the design grid
    refined ``supersample``× (cells per DOE pixel and axis). ``chain``: the mask set's alignment chain (default:
    read from the manifest beside the design folder). ``device``: where the PSFs are propagated ("auto", "cpu",
    "cuda", "cuda:N"; None: the current default, ``doefab._devices.default_device``)."""

    _LIVE: weakref.WeakSet = weakref.WeakSet()  # the process's judges (``_free_reliefs``)
    KEEP_BYTES = 256 * 2**20  # PSFs ``reuse`` keeps: a tornado's coded halves (12 of 4.5 MB for a 31-band grating)

    def __init__(self, design_dir, supersample: int = 1, threads: int | None = None, margin: float = DEFAULT_MARGIN,
                 chain: dict | None = None, device=None):
        from doefab.design.design import Design
        from doefab.fabrication.bitplanes import bit_planes
        from doefab.fabrication.levels import level_step
        from doefab.tasks import get_task
        from doefab.tolerance.relief import ReliefModel, corner_bias, plain_columns

        self.device = resolve_device(device)
        if threads:
            torch.set_num_threads(threads)
        if isinstance(design_dir, Design):  # an in-memory design (a block of one, for the grid study)
            d, self.design_dir = design_dir, None
        else:
            self.design_dir = Path(design_dir)
            d = Design.load(self.design_dir)
        self.design, self.supersample, self.margin = d, supersample, float(margin)
        self.task = get_task(d.task, **d.task_params)
        self.task.bind(d.camera)
        self.fine = refined_camera(d.camera, supersample)
        planes = bit_planes(d.levels, d.n_levels)
        self.n_masks = planes.shape[0]
        self.relief = ReliefModel(planes, d.camera.doe_pitch, supersample)
        self.corner_px2 = [corner_bias(p, 1.0) for p in planes]  # bias (px) per px² of corner radius
        self.plain_from = plain_columns(planes) * supersample  # grid column from which the design is plain
        self.step = level_step(d.camera, d.n_levels)
        self.chain = chain or alignment_chain(self.design_dir, self.n_masks)
        self._plans: dict = {}
        self._uncoded = None
        self._relief_cache: tuple = (None, None)
        PSFJudge._LIVE.add(self)
        self._kept: OrderedDict = OrderedDict()  # {(source, half): PSF} of the latest PSFs computed (``reuse``)
        self._plain_of: OrderedDict = OrderedDict()  # {source: the key its plain half is kept under}
        self._min_kernel = 0  # part PSFs are computed at this kernel at least (``computing_at``)
        self._nominal = None
        self.seconds_per_psf = None

    @property
    def nominal(self) -> torch.Tensor:
        """The error-free part's coded PSF at the task's kernel (computed on first use; ``seconds_per_psf``: its
        time)."""
        if self._nominal is None:
            t = time.perf_counter()
            with torch.no_grad():
                self._nominal = self.psfs(PartErrors())["coded"].double()
            self.seconds_per_psf = time.perf_counter() - t
        return self._nominal

    def reuse(self, source: str, halves, kernel: int | None, compute, plain=None) -> dict:
        """{half: PSF} of ``source`` (a part's errors or a height map's digest) at ``kernel``: each half served
        from the PSF kept for the same source at a kernel at least as large (pixel centres sit at (k − K//2)·p
        for every K, so a smaller kernel is the centre crop of a larger one, to float rounding), the rest from
        ``compute(todo)``, which computes only the halves ``todo`` (at ``kernel`` or larger). ``plain``: where
        given, the plain half is kept under the key ``plain()`` gives (``MountedPlan.plain_key``; ``_plain_key``).
        The latest PSFs are kept, up to ``KEEP_BYTES``: a network-level part pays once for the coded PSF its PSF
        metric and its network both use, the tornado's network pass for the coded halves its PSF-level pass
        computed, and a part whose relief leaves the plain half plain glass for nothing of that half that a part
        with its decenter computed."""
        keys = {h: self._plain_key(source, plain) if h == "uncoded" and plain else source for h in halves}
        k = int(kernel or self.task.kernel_size)

        def crop(v: torch.Tensor) -> torch.Tensor:
            c = v.shape[-1] // 2 - k // 2
            return v if v.shape[-1] == k else v[..., c:c + k, c:c + k]
        got = {}
        for h in halves:
            kept = self._kept.get((keys[h], h))
            if kept is not None and k <= kept.shape[-1]:
                got[h] = crop(kept).clone()
                self._kept.move_to_end((keys[h], h))
        todo = tuple(h for h in halves if h not in got)
        if todo:
            out = compute(todo)
            self._keep({(keys[h], h): out[h] for h in todo})
            for h in todo:
                got[h] = crop(out[h])
        return {h: got[h] for h in halves}

    def keep(self, source: str, psfs: dict) -> None:
        """Keep ``psfs`` ({half: PSF before any PSF-level effect}) of ``source`` (``source_of``) for ``reuse``,
        the oldest others dropped beyond ``KEEP_BYTES`` (these stay)."""
        self._keep({(source, h): v for h, v in psfs.items()})

    def _keep(self, entries: dict) -> None:
        for key, v in entries.items():
            self._kept[key] = v.detach().clone()
            self._kept.move_to_end(key)
        while len(self._kept) > len(entries) and sum(v.nbytes for v in self._kept.values()) > self.KEEP_BYTES:
            self._kept.popitem(last=False)

    def take_planes(self, other: PSFJudge, source: str) -> None:
        """Keep, for ``reuse``, the PSFs ``other`` keeps for ``source`` (``source_of``) at this judge's planes, when
        ``other`` (a judge of the same grid, margin and chain) is on planes that hold them all (the network judge's
        rendering planes: a PSF at a plane is the same whichever other planes are computed with it, so they serve
        the part's PSF metric on the network's planes); else nothing."""
        take = planes_among(self.design.depths, other.design.depths)
        plain = other._plain_of.get(source, source)
        got = {(s, h): v[take] for (s, h), v in other._kept.items()
               if s == source or (s, h) == (plain, "uncoded")} if take is not None else {}
        if got:
            self._keep(got)
            self._plain_key(source, lambda: plain)

    @contextmanager
    def computing_at(self, kernel: int | None):
        """Within: part PSFs are computed at ``kernel`` at least (and cropped to what is asked), so that a pass
        at that larger kernel which follows (the networks') is served from them."""
        old, self._min_kernel = self._min_kernel, int(kernel or 0)
        try:
            yield self
        finally:
            self._min_kernel = old

    def plan(self, halves=("coded",), decenter: float = 0.0, kernel: int | None = None):
        """The mounted-part PSF model for these halves, reaching at least ``decenter`` beyond the centre line."""
        from doefab.tolerance.mounted import MountedPlan

        margin = self.margin
        while abs(decenter) > margin:
            margin *= 2
        k = kernel or self.task.kernel_size
        key = (tuple(halves), margin, k)
        if key not in self._plans:
            d = self.design
            self._plans[key] = MountedPlan(self.fine, d.wavelengths, d.depths, k, halves, margin, device=self.device)
        return self._plans[key]

    def mask_errors(self, err: PartErrors):
        """The part's errors as the relief model takes them (SI units)."""
        from doefab.tolerance.relief import MaskErrors

        shifts, rots = compose_overlay(err, self.chain, self.n_masks)
        pitch = self.design.camera.doe_pitch
        r_px = err.corner_rounding / pitch
        bias = tuple(err.edge_bias + c * r_px ** 2 * pitch for c in self.corner_px2)
        return MaskErrors(tuple(shifts), tuple(rots), bias, err.mount_rotation)

    def field(self, err: PartErrors, plan):
        """``field(i)``: the part's relief transmittance at wavelength i on the plan's window, relative to the
        plain glass. Only the columns the relief can reach are computed (beyond the design's plain boundary,
        moved by the masks' and the mount's errors, the glass is plain); a mount rotation turns whichever is
        smaller, the pattern areas or the wavelengths' transmittances."""
        (r0, r1), (c0, c1) = plan.window
        th = float(err.mount_rotation)
        me = self.mask_errors(err)
        cells = self.relief.n
        reach = abs(th) * cells + max(abs(v) for s in me.shifts for v in s) / self.relief.cell + 4
        # the relief's own extent, not the plan's (which depends on the halves asked for): a part's coded half is
        # the same whether its plain half is computed too (``reuse`` relies on it)
        c_end = min(cells, max(c0 + 1, int(self.plain_from + reach)))
        key = (json.dumps(err.to_json(), sort_keys=True, default=str), r0, r1, c0, c_end)
        if self._relief_cache[0] != key:  # one part's relief serves its coded-only and its two-half PSFs
            self._free_reliefs()
            self._relief_cache = (key, self._relief_fields(err, me, plan, (r0, r1), (c0, c_end)).to(self.device))
        fields, ones = self._relief_cache[1], None
        if c_end < c1:  # plain glass beyond the relief's reach
            ones = torch.ones(r1 - r0, c1 - c_end, dtype=torch.complex64, device=self.device)

        def at(i: int) -> torch.Tensor:
            f = fields[i].to(self.device).reshape(r1 - r0, c_end - c0)[:, :c1 - c0]
            return f if ones is None else torch.cat([f, ones], dim=1)
        return at

    def _free_reliefs(self) -> None:
        """Free the relief this judge keeps, and those the process's judges on other grids keep, before a new relief
        is built: a study holds a judge per grid, and on a 31-band design a kept relief is a transmittance of 8
        bytes per cell and band (or, above ``fields.FIELD_BYTES``, the pattern areas, 4 bytes per cell and
        pattern) (``doefab tolerance --samples 1`` of a 31-band design of 634 DOE pixels on the 4× and 8× grids
        peaked at 5.9 and 8.1 GB with the last part's relief held while the next was built, at 4.1 and 6.1-6.5 GB
        without). Judges on the same grid keep theirs: a network judge's rendering judge and its PSF judge take the
        same part in turn, each for more than one set of halves."""
        for other in list(PSFJudge._LIVE):
            if other is self or other.supersample != self.supersample:
                other._relief_cache = (None, None)

    def _relief_fields(self, err: PartErrors, me, plan, rows, cols):
        """[W, cells] the part's relief transmittance of the window rows × cols, relative to the plain glass
        (``fields.relief_fields``: a tensor, or one wavelength at a time for a large grid)."""
        from doefab.tolerance.fields import relief_fields
        from doefab.tolerance.relief import pattern_heights

        (r0, r1), (c0, c_end) = rows, cols
        full = (1 << self.n_masks) - 1
        heights = pattern_heights(self.n_masks, self.step, err.for_masks(self.n_masks).depth_scale) - full * self.step
        # a tilted die: the light crosses each step at the tilt's angle (a longer optical path, sources.py)
        n_of = self.design.camera.material.index
        phases = [plan.phase_per_metre(i) * (1.0 if not err.mount_tilt else
                                             tilt_phase_factor(float(err.mount_tilt), float(n_of(wl))))
                  for i, wl in enumerate(self.design.wavelengths)]
        rough = None
        if err.roughness > 0:
            r, resid = roughness_field((r1 - r0, c_end - c0), self.relief.cell, err.roughness, err.roughness_corr,
                                       err.seed)
            rough = (torch.from_numpy(r.reshape(-1)).float(), resid)
        return relief_fields(self.relief, me, heights, phases, rows, cols, rough)

    def psfs(self, err: PartErrors, halves=("coded",), kernel: int | None = None) -> dict:
        """{half: (n_depths, n_wavelengths, K, K)} PSFs of the part."""
        if any(not 0 <= v < 0.5 for v in err.crosstalk):
            raise DoefabError("crosstalk ratios must be in [0, 0.5)")
        source = self.source_of(err)
        k = int(kernel or self.task.kernel_size)
        shared = err.axial_gap == 0 or self.fine.doe_is_stop  # a gap in front of a lens stop mixes the window
        big = max(k, self._min_kernel) if shared else k

        def compute(todo):
            plan = self.plan(halves, err.mount_shift[0], big)
            got = plan.psfs(self.field(err, plan), decenter=err.mount_shift, gap=err.axial_gap, halves=todo)
            return to_device(got, "cpu")
        def plain():
            plan = self.plan(halves, err.mount_shift[0], big)
            return plan.plain_key(self.field(err, plan), err.mount_shift, err.axial_gap)
        out = self.reuse(source, halves, k, compute, plain) if shared else compute(halves)
        return apply_psf_effects(out, err)  # the sources of error that act after the pupil (none shipped)

    def _plain_key(self, source: str, key_of) -> str:
        """The key ``source``'s plain half is kept under: the one it was given, ``source`` itself when kept under it,
        else ``key_of()`` (``MountedPlan.plain_key``; None: ``source``). The latest 256 are remembered."""
        if source not in self._plain_of:
            if (source, "uncoded") in self._kept:
                return source
            self._plain_of[source] = key_of() or source
            if len(self._plain_of) > 256:
                self._plain_of.popitem(last=False)
        self._plain_of.move_to_end(source)
        return self._plain_of[source]

    def source_of(self, err: PartErrors | None = None, height=None) -> str:
        """``psf_source`` of a part (or a height map) as this judge keys its PSFs."""
        return psf_source(err, height, self.fine.doe_is_stop)

    def uncoded(self) -> torch.Tensor:
        """The nominal plain half's PSF (crosstalk at PSF level)."""
        if self._uncoded is None:
            self._uncoded = self.psfs(PartErrors(), halves=("uncoded",))["uncoded"].double()
        return self._uncoded

    def height_psfs(self, height, halves=("coded",), kernel: int | None = None) -> dict:
        """{half: PSF} of an explicit height map (metres, on the judge's grid; the quantization study)."""
        h = torch.as_tensor(np.asarray(height, np.float64))
        source = psf_source(height=h)

        def field(plan):
            (r0, r1), (c0, c1) = plan.window
            rel = (h[r0:r1, c0:c1] - ((1 << self.n_masks) - 1) * self.step).to(self.device)

            def at(i: int) -> torch.Tensor:
                ph = (plan.phase_per_metre(i) * rel).float()
                return torch.polar(torch.ones_like(ph), ph)
            return at

        def compute(todo):
            plan = self.plan(halves, 0.0, kernel)
            with torch.no_grad():
                return to_device(plan.psfs(field(plan), halves=todo), "cpu")

        def plain():
            plan = self.plan(halves, 0.0, kernel)
            return plan.plain_key(field(plan))
        return self.reuse(source, halves, kernel, compute, plain)

    def psf_from_height(self, height) -> torch.Tensor:
        """Coded PSF of an explicit height map (metres) on the judge's grid."""
        return self.height_psfs(height)["coded"].double()

    def coded_view(self, coded: torch.Tensor, err: PartErrors) -> torch.Tensor:
        """The coded view the camera delivers: Eq. 29's mix with the plain half, unmixed with the calibrated
        estimate when the camera is calibrated (ratios at the sensor's centre column, where the PSF is)."""
        if not any(err.crosstalk):
            return coded
        from doefab.imaging.crosstalk import mix_crosstalk, unmix_crosstalk
        from doefab.tolerance.errors import crosstalk_ratios

        a, b, a_hat, b_hat = (float(v[0]) for v in crosstalk_ratios(err, [0.0]))
        left, right = mix_crosstalk(self.uncoded(), coded, a, b)  # left view = plain half, right = coded half
        if not err.calibrated:
            return right
        return unmix_crosstalk(left, right, a_hat, b_hat)[1]

    def score(self, coded: torch.Tensor, err: PartErrors | None = None) -> dict:
        """Task metric (mean, worst) and L1 distance to the nominal PSF (summed over pixels, mean over entries)."""
        if err is not None:
            coded = self.coded_view(coded, err)
        m = self.task.metric(coded.float(), self.fine)
        l1 = float((coded - self.nominal).abs().sum(dim=(-1, -2)).mean())
        return {"metric": m["value"], "worst": m["worst"], "l1_to_nominal": l1}

    def evaluate(self, err: PartErrors) -> dict:
        with torch.no_grad():
            return self.score(self.psfs(err)["coded"].double(), err)
