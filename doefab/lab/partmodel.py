"""The part model a diagnosis fits: a fabricated part's PSFs at a measured pair's bands and planes.

The model is the one ``doefab tolerance`` draws parts from (``tolerance.judge.PSFJudge`` on the design grid, 1×):
per mask (mask 1 = the shallowest etch, plate 1 of the mask set's manifest) an etch depth scale and an overlay
(x, y) relative to the plate it aligns to; one edge bias; the mount's decenter (x across the split, y along it),
rotation and axial gap. Corner rounding is held at the budget's value (every part carries it alike); mask
rotations and roughness are not fitted (a roughness is a random surface whose draw no PSF pins down), and neither
is crosstalk (each half of a measured pair is recorded with the other half blocked).

Each error is handled in units of its budget σ (``tolerance.kinds``: per axis for an overlay; a uniform decenter
±d has σ = d/√3); an error the PSFs cannot respond to is held at its nominal value with the reason
(``Param.reason``): an axial gap when the DOE is the aperture stop, a decenter along the split when every source
is at the focus distance, an error the budget gives no spread.

The model's PSFs, like the measured ones, are each scaled per half, plane and band to the error-free part's light
in the kernel (``doefab calibrate`` normalises the measured pair so; rescaling it here is a no-op then).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from doefab.errors import DoefabError
from doefab.tolerance.errors import PartErrors

__all__ = ["Param", "parameters", "to_errors", "scaled", "check_pair", "PartModel", "held_changes", "held_errors",
           "BOUND", "STEP", "ETCH_PRECISION", "HELD_DRAWS", "HOLD_DRAWS", "MEAN_SPREAD"]

BOUND = 6.0  # the fit's bounds, budget σ either side of nominal
FINE = 2  # the grid of the fit's last steps, times the design grid
STEP = 0.05  # the Jacobian's central-difference step, budget σ
RECENT = 4  # parts whose PSFs a model keeps
# bytes of PSFs the model's judges keep for reuse (``PSFJudge.KEEP_BYTES``): none beyond the latest part's. A fit's
# parts are nearly all new, so a larger cache served few of them, and the small PSFs it held, kept among each
# part's large transient buffers, fragmented the heap (``benchmarks/diagnose_memory.py``, a 1276² grid: with the
# judge's default cache the process grew from 0.93 to 1.94 GB over parts 50–400, about 3 MB per part, while the
# PSFs it held took 0.087 GB; with this setting it stays at 0.73–0.78 GB, at 0.39 s per part against 0.40)
JUDGE_KEEP_BYTES = 0
HELD_DRAWS = 16  # parts drawn from the budget's errors the fit holds, for their share of the uncertainty
HOLD_DRAWS = 32  # parts drawn likewise for the fit's model of them (``PartModel.hold``)
ETCH_PRECISION = 0.01  # an etch depth scale is identified with σ at most 1 %: 2σ within ±2 % (a re-make's decision)
MEAN_SPREAD = 1.0  # the held errors' mean PSF change is known to this fraction (a part's roughness is not the budget's)


@dataclass(frozen=True)
class Param:
    """One error of the part model: ``key`` (a diagnosis.json ``errors`` key without its unit), ``mask`` (0-based,
    per-mask errors), ``axis`` ("x"/"y" or None), its ``unit`` for people and ``si`` SI units per unit, the budget's
    one ``sigma`` (SI), its ``nominal`` value (SI), the ``reason`` it is held there (empty: fitted) and the
    ``precision`` (SI, a σ) a decision on it needs: above it the error is not identified (``lab.uncertainty``)."""

    key: str
    mask: int | None
    axis: str | None
    unit: str
    si: float
    sigma: float
    nominal: float
    reason: str = ""
    precision: float = math.inf

    @property
    def shown(self) -> tuple[str, float]:
        """(the unit people read it in, the factor from ``unit`` to it): an etch depth scale in %, others as is."""
        return ("%", 100.0) if self.key == "etch_depth_scale" else (self.unit, 1.0)

    @property
    def label(self) -> str:
        names = {"etch_depth_scale": "etch depth", "overlay": "overlay", "edge_bias": "edge bias",
                 "mount_decenter": "decenter", "mount_rotation": "mount rotation", "axial_gap": "axial gap"}
        where = f" mask {self.mask + 1}" if self.mask is not None else ""
        return names[self.key] + where + (f" {self.axis}" if self.axis else "")


def parameters(budget: dict, n_masks: int, camera, depths) -> list[Param]:
    """The part model's errors for a design of ``n_masks`` masks on ``camera``, recorded at ``depths`` (metres),
    with the budget's σ of each (``tolerance.kinds``, per axis for an overlay)."""
    from doefab.tolerance.mounted import stop_case
    from doefab.tolerance.errors import nominal_gap
    from doefab.tolerance.kinds import kind

    def s(name):
        return kind(name).from_budget(budget)
    etch, ov, bias = s("etch depth (all plates alike)"), s("mask overlay") / math.sqrt(2), s("edge bias")
    dec, rot, gap = s("decenter across split"), s("mount rotation"), s("axial gap spread")
    in_focus = all(z == camera.focus_distance for z in depths)
    out = []
    for m in range(n_masks):
        out.append(Param("etch_depth_scale", m, None, "", 1.0, etch, 1.0, precision=ETCH_PRECISION))
    for m in range(n_masks):
        out += [Param("overlay", m, a, "µm", 1e-6, ov, 0.0) for a in "xy"]
    out.append(Param("edge_bias", None, None, "µm", 1e-6, bias, 0.0))
    out.append(Param("mount_decenter", None, "x", "mm", 1e-3, dec, 0.0))
    out.append(Param("mount_decenter", None, "y", "mm", 1e-3, dec, 0.0,
                     "every recorded source is at the focus distance, where a decenter along the split only tilts "
                     "the wavefront: record a plane away from focus to see it" if in_focus else ""))
    out.append(Param("mount_rotation", None, None, "°", math.pi / 180, rot, 0.0))
    out.append(Param("axial_gap", None, None, "mm", 1e-3, gap, nominal_gap(budget),
                     stop_case(camera) + ": the PSFs do not depend on it" if camera.doe_is_stop else ""))
    return [p if p.sigma > 0 or p.reason else
            replace(p, reason="the budget gives it no spread (σ = 0): held at its nominal value") for p in out]


def to_errors(params: list[Param], x, base: PartErrors, n_masks: int) -> PartErrors:
    """The part whose fitted errors sit ``x`` budget σ from nominal (one entry per fitted parameter, in order)."""
    depth, ov = [1.0] * n_masks, [[0.0, 0.0] for _ in range(n_masks)]
    v = {}
    free = iter(np.asarray(x, np.float64))
    for p in params:
        val = p.nominal if p.reason else p.nominal + float(next(free)) * p.sigma
        if p.key == "etch_depth_scale":
            depth[p.mask] = val
        elif p.key == "overlay":
            ov[p.mask]["xy".index(p.axis)] = val
        else:
            v[(p.key, p.axis)] = val
    return replace(base, depth_scale=tuple(depth), overlay=tuple(tuple(o) for o in ov),
                   edge_bias=v[("edge_bias", None)], mount_rotation=v[("mount_rotation", None)],
                   mount_shift=(v[("mount_decenter", "x")], v[("mount_decenter", "y")]),
                   axial_gap=v[("axial_gap", None)])


def scaled(params: list[Param], err: PartErrors, n_masks: int) -> np.ndarray:
    """``err``'s fitted errors in budget σ from nominal (the inverse of ``to_errors``)."""
    err = err.for_masks(n_masks)
    out = []
    for p in params:
        if p.reason:
            continue
        i = "xy".index(p.axis) if p.axis else 0
        val = {"etch_depth_scale": lambda: err.depth_scale[p.mask], "overlay": lambda: err.overlay[p.mask][i],
               "edge_bias": lambda: err.edge_bias, "mount_decenter": lambda: err.mount_shift[i],
               "mount_rotation": lambda: err.mount_rotation, "axial_gap": lambda: err.axial_gap}[p.key]()
        out.append((float(val) - p.nominal) / p.sigma)
    return np.asarray(out)


def _index(have, want, what: str, shown) -> list[int]:
    """Where each of ``want`` sits in ``have`` (a DoefabError naming one the design does not have)."""
    out = []
    for v in want:
        hit = [i for i, h in enumerate(have) if (math.isinf(h) and math.isinf(v) and h == v)
               or (math.isfinite(h) and math.isfinite(v) and math.isclose(h, v, rel_tol=1e-6))]
        if not hit:
            raise DoefabError(f"the measured pair has a {what} of {shown(v)} that the design does not have "
                              f"({', '.join(shown(h) for h in have)}): calibrate with the design the part was made "
                              f"from (doefab calibrate --design DIR)")
        out.append(hit[0])
    return out


def check_pair(measured, design) -> tuple[tuple, list[int], list[int], int]:
    """(halves, band indices, plane indices into the design's, kernel) of a measured pair that ``design`` can
    model: its coded half present, its sensor pitch the design camera's, its bands and planes the design's, its
    PSFs on the design task's kernel (one DoefabError naming the first mismatch and the fix)."""
    halves = tuple(h for h in ("coded", "uncoded") if getattr(measured, h, None) is not None)
    if "coded" not in halves:
        raise DoefabError("the measured pair has no coded half: calibrate point-source recordings of the coded half "
                          "(half = \"coded\") before diagnosing")
    cam = design.camera
    if not math.isclose(measured.sensor_pitch, cam.sensor_pitch, rel_tol=1e-6):
        raise DoefabError(f"the measured pair's sensor pitch {measured.sensor_pitch * 1e6:.4g} µm differs from the "
                          f"design camera's {cam.sensor_pitch * 1e6:.4g} µm: calibrate with this design's camera")
    wl = _index(design.wavelengths, measured.wavelengths, "band", lambda v: f"{v * 1e9:.4g} nm")
    dz = _index(design.depths, measured.depths, "source distance", lambda v: f"{v:g} m")
    kernel, want = int(measured.coded.shape[-1]), design.kernel_size
    if kernel != want:
        raise DoefabError(f"the measured pair's PSFs are {kernel} px across but the design's task uses {want} px: "
                          f"calibrate with this design (it crops to its kernel)")
    return halves, wl, dz, kernel


class PartModel:
    """The part model at a measured pair's bands and planes (``design``: a design folder, a mask set or a
    ``Design``) and the residuals of a part against that pair. ``evaluations`` counts the parts computed."""

    def __init__(self, design, measured, budget: dict, device=None):
        from doefab.design.design import Design, design_folder_of
        from doefab.fabrication.process import mask_count
        from doefab.tolerance.judge import DEFAULT_MARGIN, PSFJudge, alignment_chain

        self.design_dir = None if isinstance(design, Design) else design_folder_of(design)
        self.design = design if isinstance(design, Design) else Design.load(self.design_dir)
        d, cam = self.design, self.design.camera
        self.halves, self.wl, self.dz, self.kernel = check_pair(measured, d)
        self.n_masks, self.budget = mask_count(d.n_levels), budget
        self.params = parameters(budget, self.n_masks, cam, measured.depths)
        self.base = PartErrors(corner_rounding=budget.get("lithography", {}).get("corner_rounding_um", 0.0) * 1e-6)
        sub = replace(d, wavelengths=tuple(measured.wavelengths), depths=tuple(measured.depths))
        # the sample grid reaches past the split as far as the budget's decenter does (a fit beyond widens it)
        reach = budget.get("mounting", {}).get("decenter_max_mm", 0.0) * 1e-3
        self.judge = PSFJudge(sub, 1, margin=max(DEFAULT_MARGIN, 1.2 * reach),
                              chain=alignment_chain(self.design_dir, self.n_masks), device=device)
        self.judge.KEEP_BYTES = JUDGE_KEEP_BYTES
        self._fine, self._recent = None, {}
        with torch.no_grad():
            nominal = self.judge.psfs(PartErrors(), halves=self.halves, kernel=self.kernel)
        self.light = np.stack([nominal[h].double().numpy().sum(axis=(-1, -2), keepdims=True) for h in self.halves])
        self.measured = self._scaled(np.stack([np.asarray(getattr(measured, h), np.float64) for h in self.halves]))
        self.weight = np.ones_like(self.measured)  # 1 / the pixels' noise σ (``reweight``)
        self.offset = 0.0  # the mean PSF change that the errors the fit holds make (``hold``)
        self.basis = None  # (Q [n, k], f [k]): the whitening of their spread (``hold``)
        self.evaluations = 0
        self.tick = None  # called after each part computed (a progress bar)

    @property
    def free(self) -> list[Param]:
        return [p for p in self.params if not p.reason]

    def _scaled(self, a: np.ndarray) -> np.ndarray:
        """Each half of each plane and band scaled to the error-free part's light in the kernel."""
        return a * (self.light / np.maximum(a.sum(axis=(-1, -2), keepdims=True), 1e-30))

    def errors(self, x) -> PartErrors:
        return to_errors(self.params, x, self.base, self.n_masks)

    def psfs(self, err: PartErrors, fine: bool = False, scale: bool = True) -> np.ndarray:
        """[halves, D, W, K, K] the part's PSFs at the measured entries, scaled as the measured ones (``scale``
        False: with their own light); ``fine``: on the grid ``FINE`` times finer (``PSFJudge(supersample=FINE)``,
        built on first use)."""
        key = (repr(err), fine)
        out = self._recent.pop(key, None)
        if out is None:
            out = self._compute(err, fine)
        self._recent[key] = out  # the last few parts: a diagnosis asks for its fitted part's PSFs several times
        while len(self._recent) > RECENT:
            self._recent.pop(next(iter(self._recent)))
        return self._scaled(out) if scale else out.copy()

    def _compute(self, err: PartErrors, fine: bool) -> np.ndarray:
        """[halves, D, W, K, K] the part's PSFs with their own light (one part computed, ``evaluations`` counts)."""
        judge = self.judge
        if fine:
            if self._fine is None:
                from doefab.tolerance.judge import PSFJudge

                j = self.judge
                self._fine = PSFJudge(j.design, FINE, margin=j.margin, chain=j.chain, device=j.device)
                self._fine.KEEP_BYTES = JUDGE_KEEP_BYTES
            judge = self._fine
        with torch.no_grad():
            got = judge.psfs(err, halves=self.halves, kernel=self.kernel)
        self.evaluations += 1
        if self.tick is not None:
            self.tick()
        return np.stack([got[h].double().numpy() for h in self.halves])

    def residual(self, x, fine: bool = False) -> np.ndarray:
        """The weighted residual vector of the part ``x`` (budget σ) against the measured pair: the model's PSFs
        with the held errors' mean change (``hold``), less the measured ones, weighted per pixel and whitened
        against the held errors' spread."""
        return self.whiten(((self.psfs(self.errors(x), fine) + self.offset - self.measured) * self.weight).ravel())

    def hold(self, changes: np.ndarray) -> None:
        """Model the errors the fit holds from ``changes`` [k, n]: PSF changes they make in k drawn parts
        (unweighted, ``held_changes``). Their mean joins the model's PSFs (``offset``: a rough surface scatters
        light from every part alike) and their spread, in the current weights, joins the noise: the residual is
        whitened by (I + UUᵀ)^(−1/2), U's columns the weighted deviations from the mean over √(k − 1) and the
        weighted mean times ``MEAN_SPREAD`` (a part's roughness is not the budget's: the mean's size is uncertain
        too), so the fit gives less weight to what the held errors could have made (generalised least squares).
        ``hold(None)`` undoes it.
        Example: ``model.hold(held_changes(model, x, HOLD_DRAWS))``."""
        c = None if changes is None else np.asarray(changes, np.float64)
        if c is None or len(c) < 2 or not np.any(c):  # nothing held, or nothing it changes
            self.offset, self.basis = 0.0, None
            return
        mean = c.mean(axis=0)
        w = self.weight.ravel()
        u = np.concatenate([(c - mean) / math.sqrt(len(c) - 1), MEAN_SPREAD * mean[None]]) * w
        q, s, _ = np.linalg.svd(u.T, full_matrices=False)
        self.offset = mean.reshape(self.measured.shape)
        self.basis = (q, 1.0 / np.sqrt(1.0 + s * s) - 1.0)

    def whiten(self, v: np.ndarray) -> np.ndarray:
        """(I + UUᵀ)^(−1/2)·v for a weighted residual (or its change) ``v`` of length n (``hold``)."""
        if self.basis is None:
            return v
        q, f = self.basis
        return v + q @ (f * (q.T @ v))

    def misfit(self, x) -> float:
        r = self.residual(x)
        return float(r @ r)

    def reweight(self, x) -> list[dict]:
        """Weigh each pixel by 1/σ from a noise model σ² = a·PSF + b per half, plane and band (shot noise grows
        with the light a pixel gets; b: the read noise and the dark's), fitted by non-negative least squares to
        the squared residuals of the part ``x`` against the model's PSF (not the noisy measured one, which would
        make the weights follow the noise). Returns [{"a", "b"}] per entry, in the pair's order."""
        from scipy.optimize import nnls

        m = np.clip(self.psfs(self.errors(x)) + self.offset, 0.0, None)
        r2 = (m - self.measured) ** 2
        k2 = m.shape[-2] * m.shape[-1]
        flat_m, flat_r = m.reshape(-1, k2), r2.reshape(-1, k2)
        var, out = np.empty_like(flat_m), []
        for i, (mi, ri) in enumerate(zip(flat_m, flat_r)):
            sm, sr = max(float(mi.max()), 1e-300), max(float(ri.mean()), 1e-300)
            (a, b), _ = nnls(np.stack([mi / sm, np.ones_like(mi)], axis=1), ri / sr)
            a, b = a * sr / sm, max(b * sr, 1e-3 * sr)  # a floor: no pixel weighs more than the mean's 1000 times
            var[i] = a * mi + b
            out.append({"a": float(a), "b": float(b)})
        self.weight = 1.0 / np.sqrt(var.reshape(m.shape))
        return out


def held_changes(model: "PartModel", x: np.ndarray, draws: int, seed: int = 0, stream: int = 40) -> np.ndarray:
    """[draws, n] the change of the fitted part's PSFs (on the finer grid, unweighted) when the errors the fit holds
    take values drawn from the budget (``tolerance.errors.sample_errors``, draws of ``stream``): the masks' rotations
    and the surface roughness, and each error held for a reason (a decenter along the split at focus, an axial gap
    at the stop). A real part carries them."""
    from dataclasses import replace

    from doefab.tolerance.errors import sample_errors

    fitted = model.errors(x)
    held = {(p.key, p.axis) for p in model.params if p.reason and p.sigma > 0}
    rng = np.random.default_rng([seed, stream])
    base = model.psfs(fitted, fine=True)
    out = []
    for i in range(draws):
        d = sample_errors(model.budget, rng, seed=10**6 * (stream - 39) + 1000 * seed + i, n_masks=model.n_masks)
        y = d.mount_shift[1] if ("mount_decenter", "y") in held else fitted.mount_shift[1]
        part = replace(fitted, rotation=d.rotation, roughness=d.roughness, roughness_corr=d.roughness_corr,
                       seed=d.seed, mount_shift=(fitted.mount_shift[0], y),
                       axial_gap=d.axial_gap if ("axial_gap", None) in held else fitted.axial_gap)
        out.append((model.psfs(part, fine=True) - base).ravel())
    return np.stack(out)


def held_errors(model: "PartModel", x: np.ndarray, draws: int = HELD_DRAWS, seed: int = 0) -> np.ndarray:
    """[draws, n] ``held_changes`` of draws independent of the ones the fit holds (``PartModel.hold``), less the
    mean change that the model carries, that mean's own uncertainty added (± ``partmodel.MEAN_SPREAD`` of it in
    turn: a part's roughness is not the budget's), weighted and whitened as the residuals are: ``curvature``
    turns them into the fitted errors' spread."""
    mean = np.ravel(model.offset) * np.ones(model.measured.size)
    d = held_changes(model, x, draws, seed) - mean
    d = d + MEAN_SPREAD * np.where(np.arange(draws) % 2 == 0, 1.0, -1.0)[:, None] * mean
    return np.stack([model.whiten(row * model.weight.ravel()) for row in d])
