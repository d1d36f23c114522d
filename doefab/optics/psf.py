"""Split-aperture PSFs (the paper's Eq. 1–10 and 14): the coded (x < 0, DOE) and uncoded (x > 0) halves.

``PSFPlan`` precomputes everything that does not depend on the height map (pupil sampling, source
wavefronts, transform matrices) so that an optimiser calls it cheaply; ``split_aperture_psf`` is the
one-shot function. Both return energy fractions of the *whole* aperture's light on sensor pixels: each
half sums to about 0.5 over a large kernel.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch

from doefab import validate as _validate
from doefab._devices import resolve_device, to_device
from doefab.errors import DoefabError
from doefab.optics.camera import Camera, require_camera, window_reach
from doefab.optics.elements import as_height_tensor
from doefab.optics.propagators import make_route
from doefab.optics.propagators.base import FocalSetup, check_smooth_phase, scratch_kwargs
from doefab.optics.pupil import APERTURES, HALVES, pupil_half, source_path_difference

__all__ = ["PSFPair", "PSFPlan", "split_aperture_psf", "as_height_tensor", "describe_bands", "staircase_error",
           "staircase_step"]

SOURCE_PHASE_LIMIT = math.pi / 2  # max smooth phase change between neighbouring pupil samples (radians)


def staircase_error(step: float) -> float:
    """About how far (relative L2) a structured height map's PSF is off at a plane out of focus, where the point's
    wavefront changes by ``step`` rad between pupil samples at the pupil's rim.

    The pupil holds the wavefront constant over each sample (a DOE pixel at ``pupil_oversample`` 1) and a
    structured map's PSF takes the flat pixel's envelope, so the wavefront's tilt inside a pixel is lost: the
    light of a pixel at radius r is damped by sinc(Δφ_r / 2π), Δφ_r = step · r / R, which on a uniformly lit disc
    is a relative L2 error of step² / (12 √3) and a lost fraction step² / 24 of the light (the sinc's second
    order). Measured (``benchmarks/psf_defocus_staircase.py``), the half-ring's start follows it within 15 % from
    0.45 to 1.4 rad and is 2× above it at 0.1 rad, where light diffracted onto the envelope's slope adds a part
    linear in the step; a map that scatters light widely is further above it at small steps (7.7× at 0.1 rad,
    1.7× at 0.45). ``pupil_oversample`` q divides the step by q. A plain (flat) half takes no envelope and stays
    within the routes' sampling limit, ``SOURCE_PHASE_LIMIT``.

    Example: ``staircase_error(0.45)`` is about 0.0097 (1 %)."""
    return float(step) ** 2 / (12 * math.sqrt(3))


def staircase_step(error: float) -> float:
    """The wavefront's phase step per pupil sample (rad) at which ``staircase_error`` reaches ``error``.

    Example: ``staircase_step(0.01)`` is about 0.456 rad."""
    return math.sqrt(float(error) * 12 * math.sqrt(3))


@dataclass
class PSFPair:
    """Coded and uncoded PSFs.

    Attributes:
        coded, uncoded: (n_depths, n_wavelengths, K, K) tensors of energy fractions (or None when not
            asked for); rows are y (row 0 = top), columns x, pixel (K//2, K//2) on the chief ray.
        wavelengths: metres.  depths: metres (``inf`` = plane wave).  sensor_pitch: metres.
        full: the whole aperture's PSF (when asked for).  camera: the camera it was computed for (None when
            unknown, e.g. a measured pair).
        provenance: where a pair read from or written to ``psf_pair.npz`` comes from (``source``,
            ``levels_sha256``, ``recordings_sha256``, ``shifts_px``...; ``doefab.optics.psffile``), or None.

    Example:
        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
        >>> pair = doefab.split_aperture_psf(None, cam, [656e-9, 589e-9, 486e-9], [float("inf")], kernel_size=21)
        >>> tuple(pair.coded.shape), pair.depths  # (depths, wavelengths, K, K)
        ((1, 3, 21, 21), (inf,))
    """

    coded: torch.Tensor | None
    uncoded: torch.Tensor | None
    wavelengths: tuple[float, ...]
    depths: tuple[float, ...]
    sensor_pitch: float
    full: torch.Tensor | None = None
    camera: Camera | None = None
    provenance: dict | None = None

    def __post_init__(self) -> None:
        if self.camera is not None:
            require_camera(self.camera, "PSFPair.camera")

    def save(self, path, provenance: dict | None = None):
        """Write ``psf_pair.npz`` (:func:`doefab.optics.psffile.save_psf_pair`); returns its path."""
        from doefab.optics.psffile import save_psf_pair

        return save_psf_pair(self, path, provenance)

    @classmethod
    def load(cls, path) -> "PSFPair":
        """Read and check ``psf_pair.npz`` (:func:`doefab.optics.psffile.read_psf_pair`): float32 CPU tensors,
        ``camera`` None, ``provenance`` the stored dict.

        Example: ``pair = doefab.PSFPair.load("out/cal/psf_pair.npz")``"""
        from doefab.optics.psffile import read_psf_pair

        return cls(**read_psf_pair(path))

    def __getitem__(self, half: str) -> torch.Tensor:
        out = getattr(self, half, None) if half in APERTURES else None
        if out is None:
            raise DoefabError(f"the {half!r} PSF was not computed: pass halves including it")
        return out

    def system_differences(self, other: "PSFPair") -> list[str]:
        """What of the system ``other`` was computed for differs from this pair's — its bands, and its camera
        where both pairs know theirs (else its sensor pitch) — each as "what (this pair: what)"; [] when none.
        Depth planes and the PSFs' values are not compared: a fabricated part of the same design on the same
        camera is the same system."""
        out = []
        mine, theirs = tuple(self.wavelengths), tuple(other.wavelengths)
        if len(mine) != len(theirs) or not np.allclose(mine, theirs, rtol=1e-6, atol=0.0):
            out.append(f"{describe_bands(theirs)} (this pair: {describe_bands(mine)})")
        if self.camera is not None and other.camera is not None:
            out += [f"camera {f.name} {_shown(getattr(other.camera, f.name))} (this pair: "
                    f"{_shown(getattr(self.camera, f.name))})" for f in dataclasses.fields(Camera)
                    if getattr(other.camera, f.name) != getattr(self.camera, f.name)]
        elif not math.isclose(self.sensor_pitch, other.sensor_pitch, rel_tol=1e-9):
            out.append(f"sensor pitch {other.sensor_pitch * 1e6:.4g} µm (this pair: {self.sensor_pitch * 1e6:.4g} µm)")
        return out


def describe_bands(wavelengths) -> str:
    """``3 bands 656, 589, 486 nm`` (the first six of ``wavelengths`` in metres)."""
    shown = ", ".join(f"{w * 1e9:.4g}" for w in wavelengths[:6]) + (", …" if len(wavelengths) > 6 else "")
    return f"{len(wavelengths)} band{'s' if len(wavelengths) != 1 else ''} {shown} nm"


def _shown(value) -> str:
    """A camera field as a person reads it: a material by name, a length with its unit."""
    if hasattr(value, "name"):
        return str(value.name)
    return f"{value:g} m" if isinstance(value, float) and value < 1 else f"{value:g}"


def _check_window(camera: Camera, depths, k: int) -> None:
    """Refuse a centred window that cuts the plain half's geometric blur at a plane (``Camera.window_holds_blur``):
    the light past its edge would be missing from the PSFs, and the captures made with them."""
    if camera.window_holds_blur(depths, k):
        return
    z, r = camera.widest_blur(depths)
    need = camera.window_for_blur(depths)
    focus, at = ("infinity" if math.isinf(d) else f"{d:g} m" for d in (camera.focus_distance, z))
    raise DoefabError(f"the {k} px PSF window reaches {window_reach(k)} px from a point's image, and the plain half "
                      f"blurs a point at {at} into a half disc of {r:.1f} px radius (the camera focused at {focus}): "
                      f"the light beyond the window would be missing from the PSFs; widen the window to ≥ {need} px "
                      f"(PSFPlan's kernel_size, a task's task_params kernel_size, --kernel of doefab psf), bring the "
                      f"depths nearer the focus, or pass PSFPlan(check=False) to accept PSFs cut by the window")


def _check_stop(camera: Camera) -> None:
    """Refuse a camera whose lens pupil is narrower than the DOE's baffle (``Camera.lens_cuts_doe``): the lens
    would block the baffle's outer ring and split the aperture at its own stop, while the PSFs carry the whole
    baffle's light, split at the DOE."""
    if not camera.lens_cuts_doe:
        return
    pupil, doe = camera.lens_pupil_diameter, camera.aperture_diameter
    raise DoefabError(f"Camera: the lens's {pupil * 1e3:.2f} mm entrance pupil (focal_length / lens_f_number = "
                      f"{camera.focal_length * 1e3:g} mm / {camera.lens_f_number:g}) is narrower than the DOE's "
                      f"{doe * 1e3:.2f} mm baffle, so the lens would block the DOE's outer ring, which the PSFs "
                      f"carry: make the DOE the stop with aperture_diameter ≤ {math.floor(pupil * 1e6) / 1e6:g} m, "
                      f"set lens_f_number to the lens's own wide-open f-number if it opens wider (≤ "
                      f"{math.floor(camera.focal_length / doe * 1e3) / 1e3:g} holds this DOE), or pass "
                      f"PSFPlan(check=False) to accept PSFs that ignore the lens's stop")


class PSFPlan:
    """Precomputed split-aperture PSF model for one camera, wavelength list, depth list and window.

    Args:
        camera: the camera.
        wavelengths: metres.  depths: metres (> 0, ``inf`` for a plane wave).
        kernel_size: K, output window K × K sensor pixels (odd K makes the blank coded PSF the exact mirror
            of the uncoded one).
        halves: which PSFs to compute, a subset of ``("coded", "uncoded")``; ``"full"`` adds the whole
            aperture as one coherent pupil (the pair's DOE on x < 0, ``height_right`` or flat on x > 0; blank: a
            conventional camera; used for reference checks).
        route: ``"spectral"`` (default), ``"mft"``, ``"fft"`` or ``"asm"``, or a Route object.
        pupil_oversample: pupil samples per DOE pixel and axis (heights are held per DOE pixel). A structured
            map's PSF at a plane out of focus is off by about ``staircase_error(step / q)`` (the wavefront is held
            flat over each sample; ``step``: its phase change between DOE pixels, as ``doefab doctor`` prints).
        precision: ``"float32"`` (default) or ``"float64"``.
        center: (u, v) sensor position of the window's centre pixel, metres.
        check: run the routes' sampling checks and, for a centred window, check that it holds the plain half's
            defocus blur at every depth (``Camera.window_holds_blur``), and that the lens's pupil does not cut
            the DOE (``Camera.lens_cuts_doe``): refuse rather than return a wrong PSF.
        device: where the PSFs are computed: "auto" (CUDA when torch sees a GPU), "cpu", "cuda" or "cuda:N";
            None: the current default (``doefab._devices.default_device``). The plan's precomputed tensors live
            there; ``half_psf`` returns tensors there, ``__call__`` returns the pair where the height came from
            (a tensor's device; the CPU for a numpy array or a blank DOE).
        route_options: passed to the route (``pixel_nodes`` for mft, ``oversample`` for fft, ``pad`` for asm).

    Example:

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=64, doe_pitch=135e-6)  # the 8.64 mm DOE on a coarse 64² grid
        >>> plan = doefab.PSFPlan(cam, [550e-9], [float("inf")], kernel_size=31)
        >>> pair = plan(None)  # a blank DOE; a height map (metres, N × N) in its place computes its PSFs
        >>> tuple(pair.coded.shape), round(float(pair.coded.sum()), 2)  # (depths, wavelengths, K, K); half the light
        ((1, 1, 31, 31), 0.49)
    """

    def __init__(self, camera: Camera, wavelengths, depths, kernel_size: int = 255,
                 halves=HALVES, route="spectral", pupil_oversample: int = 1, precision: str = "float32",
                 center=(0.0, 0.0), check: bool = True, device=None, **route_options):
        require_camera(camera)
        self.device = resolve_device(device)
        self.camera = camera
        self.wavelengths = _validate.wavelengths(wavelengths)
        self.depths = _validate.depths(depths)
        kernel_size = _validate.number_in("kernel_size", kernel_size, 1, 8191, integer=True, unit="sensor pixels")
        halves = (halves,) if isinstance(halves, str) else tuple(halves)
        if not halves or any(h not in APERTURES for h in halves):
            raise DoefabError(f"halves must be a non-empty subset of {APERTURES}, got {halves!r}")
        if precision not in ("float32", "float64"):
            raise DoefabError(f"precision must be 'float32' or 'float64', got {precision!r}")
        self.real_dtype = torch.float32 if precision == "float32" else torch.float64
        self.halves = halves
        self.kernel_size = int(kernel_size)
        self.route = make_route(route, **route_options)
        pupil_oversample = _validate.number_in("pupil_oversample", pupil_oversample, 1, 64, integer=True)
        self.center = _validate.sensor_position("center", center)
        self.check = check
        if check:
            _check_stop(camera)
        n_idx = camera.material.index(np.asarray(self.wavelengths))
        self._k = [2 * math.pi / lam for lam in self.wavelengths]
        self._dn = [float(v) - 1.0 for v in np.atleast_1d(n_idx)]
        self._halves: dict[str, tuple] = {}
        for half in halves:
            geo = pupil_half(camera, half, pupil_oversample)
            opd = np.stack([source_path_difference(geo.r2, z, camera.focus_distance) for z in self.depths])
            support = geo.coverage > 0
            if check:
                for z, o in zip(self.depths, opd):
                    check_smooth_phase(self._k[int(np.argmin(self.wavelengths))] * o, support, SOURCE_PHASE_LIMIT,
                                       getattr(self.route, "name", "route"),
                                       f"wavefront of the point at {z:g} m", pupil_oversample)
            cov = torch.from_numpy(geo.coverage).to(self.device, self.real_dtype)
            opd_t = torch.from_numpy(opd).to(self.device, self.real_dtype)
            setups = {}
            for env in (False, True):
                setup = FocalSetup(geo.x, geo.y, geo.pitch, env, self.wavelengths, camera.sensor_distance,
                                   camera.sensor_pitch, self.kernel_size, self.center, self.real_dtype, support)
                setups[env] = setup
            if check:
                self.route.check(setups[False])
            self._halves[half] = (geo, cov, opd_t, setups, {})
        if check and not any(self.center):  # after the routes' checks: a sampling problem is told first
            _check_window(camera, self.depths, self.kernel_size)

    def _prepared(self, half: str, envelope: bool):
        geo, cov, opd, setups, cache = self._halves[half]
        if envelope not in cache:
            cache[envelope] = to_device(self.route.prepare(setups[envelope]), self.device)
        return setups[envelope], cache[envelope]

    def half_psf(self, half: str, height: torch.Tensor | None, depth_indices=None,
                 wavelength_indices=None) -> torch.Tensor:
        """(n_depths, n_wavelengths, K, K) PSF of one half; ``height`` is the full-grid map or None (flat).

        ``depth_indices`` / ``wavelength_indices`` restrict the computation to those entries of the plan's
        lists (the output then has that many depths / wavelengths, in the order given). The PSF is on the plan's
        device (``height`` is moved there, its gradient kept).
        """
        geo, cov, opd, _, _ = self._halves[half]
        if depth_indices is not None:
            opd = opd[list(depth_indices)]
        wl = range(len(self.wavelengths)) if wavelength_indices is None else list(wavelength_indices)
        h = None
        if height is not None:
            h = _on_samples(height.to(self.device)[geo.rows, geo.cols], geo.oversample)
        setup, prepared = self._prepared(half, h is not None and _structured(h, cov))
        kw = scratch_kwargs(self.route)  # the route's buffers, reused over the wavelengths (none under a gradient)
        out = []
        for i in wl:
            phase = self._k[i] * opd
            if h is not None:
                phase = phase + (self._k[i] * self._dn[i]) * h.to(self.real_dtype)
            pupil = torch.polar(cov.expand_as(phase), phase)
            out.append(self.route.intensity(pupil, i, setup, prepared, **kw))
        return torch.stack(out, dim=1) / geo.full_area

    def gap_psfs(self, doe: torch.Tensor, gap: float, halves=None) -> dict:
        """PSFs of ``halves`` (default: the plan's) when the DOE ``doe`` (full-grid heights, metres) sits
        ``gap`` metres in front of the aperture plane (``doefab.optics.gap``): {half: (D, W, K, K)}."""
        from doefab.optics.gap import gap_transmittance

        halves = self.halves if halves is None else tuple(halves)
        didx = range(len(self.depths))
        per_half = {h: [] for h in halves}
        kw = scratch_kwargs(self.route)
        for i, lam in enumerate(self.wavelengths):
            t_full = [gap_transmittance(doe, self.camera, lam, self.depths[j], gap) for j in didx]
            for half in halves:
                geo, cov, opd, _, _ = self._halves[half]
                t = _on_samples(torch.stack([tf[geo.rows, geo.cols] for tf in t_full]), geo.oversample)
                hd = _on_samples(doe[geo.rows, geo.cols], geo.oversample)
                # the coded half is a pixelated DOE (pixel envelope, as at gap 0, and like it none for a flat
                # plate); the plain half sees the DOE's diffracted light as a smooth field, as its gap-0 PSF does
                setup, prepared = self._prepared(half, half != "uncoded" and _structured(hd, cov))
                pupil = torch.polar(cov.expand_as(t.real), self._k[i] * opd) * t
                per_half[half].append(self.route.intensity(pupil, i, setup, prepared, **kw) / geo.full_area)
        return {h: torch.stack(v, dim=1) for h, v in per_half.items()}

    def __call__(self, height=None, height_right=None, gap: float = 0.0) -> PSFPair:
        """PSFs for a full-grid height map (metres; None = blank DOE) and optional right-half map.

        ``gap`` (metres, default 0): the DOE sits that far in front of the aperture plane, so its diffraction
        over the gap reaches both halves (``doefab.optics.gap``; ``height_right`` is then ignored: the DOE's
        own map covers both halves).

        Computed on the plan's device; the pair's tensors are on ``height``'s device when it is a tensor, else on
        the CPU.
        """
        back = height.device if isinstance(height, torch.Tensor) else torch.device("cpu")
        h = None if height is None else as_height_tensor(height, self.camera, "height", self.real_dtype)
        hr = None if height_right is None else as_height_tensor(height_right, self.camera, "height_right",
                                                                 self.real_dtype)
        got = None
        if gap:
            from doefab.optics.gap import check_gap

            if check_gap(gap) > 0 and h is not None:
                got = self.gap_psfs(h.to(self.device), gap)
        if got is None:
            maps = {"coded": h, "uncoded": hr}
            if "full" in self.halves:
                maps["full"] = _whole_map(*(None if m is None else m.to(self.device) for m in (h, hr)), self.camera)
            got = {half: self.half_psf(half, maps[half]) for half in self.halves}
        got = to_device(got, back)
        return PSFPair(got.get("coded"), got.get("uncoded"), self.wavelengths, self.depths, self.camera.sensor_pitch,
                       got.get("full"), self.camera)


def _whole_map(h, hr, camera: Camera):
    """The ``"full"`` pupil's map: the pair's system as one coherent pupil, ``h`` where a DOE pixel's centre lies
    in the coded half (x ≤ 0) and ``hr`` (None: flat) elsewhere. On an odd grid the column on the split line takes
    ``h`` whole (the pair gives its right half ``hr``)."""
    if h is None and hr is None:
        return None
    like = h if h is not None else hr
    centres = (torch.arange(camera.doe_pixels, device=like.device) - (camera.doe_pixels - 1) / 2)
    left = (centres <= 0)[None, :]
    return torch.where(left, h if h is not None else 0.0, hr if hr is not None else 0.0)


def _on_samples(x: torch.Tensor, q: int) -> torch.Tensor:
    """A map (or a stack of maps) held per DOE pixel, on a half's pupil samples: each pixel repeated q × q."""
    return x if q == 1 else x.repeat_interleave(q, -2).repeat_interleave(q, -1)


def _structured(h: torch.Tensor, cov: torch.Tensor) -> bool:
    """Whether the heights ``h`` vary over the pupil samples that pass light (coverage ``cov`` > 0): only a
    structured DOE has flat pixels whose far field carries the pixel envelope; a flat plate is smooth, whatever
    the map holds outside the clear aperture. (The PSF is therefore not continuous at an exactly flat map: any
    structure switches the envelope on.)"""
    seen = h.detach()[(cov > 0).to(h.device)]
    return seen.numel() > 0 and bool(seen.max() > seen.min())


def split_aperture_psf(height, camera: Camera, wavelengths, depths, kernel_size: int = 255,
                       halves=HALVES, h_right=None, **options) -> PSFPair:
    """Coded and uncoded PSFs of a split aperture (the paper's Eq. 10/14), one call.

    Args:
        height: (N, N) DOE height map over the full aperture grid, metres (numpy or torch; torch keeps
            gradients). Only its x < 0 half acts (coded half). None means a blank DOE.
        camera: the camera (doefab.Camera).
        wavelengths: metres, e.g. [656e-9, 589e-9, 486e-9].
        depths: point-source distances, metres; ``inf`` is a plane wave.
        kernel_size: K (sensor pixels); output (n_depths, n_wavelengths, K, K).
        halves: ``("coded",)``, ``("uncoded",)`` or both; only what is asked is computed.
        h_right: optional (N, N) height map whose x > 0 half acts on the uncoded half (default 0).
        **options: see :class:`PSFPlan` (route, pupil_oversample, precision, center, check, device,
            pixel_nodes…).
    Returns:
        PSFPair with energy fractions of the whole aperture's light per sensor pixel.

    Example:
        A blank DOE (both halves plain) at one wavelength and a plane wave: each half carries half the light, and a
        31-pixel window holds nearly all of it.

        >>> import doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
        >>> pair = doefab.split_aperture_psf(None, cam, [550e-9], [float("inf")], kernel_size=31)
        >>> tuple(pair.coded.shape)
        (1, 1, 31, 31)
        >>> round(float(pair.coded.sum()), 2), round(float(pair.uncoded.sum()), 2)
        (0.49, 0.49)
    """
    plan = PSFPlan(camera, wavelengths, depths, kernel_size, halves, **options)
    return plan(height, h_right)
