"""PSFs of a mounted part: its die decentered against the lens axis and the dual-pixel split, its relief as made.

A decenter moves the whole relief and the chrome baffle on it rigidly against the lens and the split; it never
changes the relief. So the relief stays on its own grid (the die frame, with the sensor's axes: a die
rotation is applied to the relief, ``relief.ReliefModel``) and what is smooth moves instead:

- the split line crosses the die frame at x = −dx; each half's coverage is its exact area on its side
  (``doefab.optics.pupil``), the baffle's disk stays centred on the die;
- the source's wavefront, relative to the plane in focus, is evaluated at the lens-frame radius |p + d|;
- a translation of the whole pupil only multiplies the sensor field by a phase ramp, so the sample grid's own
  position does not matter.

A whole-pixel decenter is thus exactly the part with the pattern moved by whole pixels, and a sub-pixel one
lies between them. The sample grid reaches ``margin`` beyond the centre line, so every decenter within it
shares one set of transform matrices.

**Which plane splits the aperture.** When the DOE's baffle is narrower than the lens's entrance pupil
(``Camera.doe_is_stop``), the baffle is the aperture stop, the exit pupil is the lens's image of the DOE and
the dual-pixel split is conjugate to the DOE itself: a gap between the DOE and the lens then moves nothing and
is not propagated. Only when the lens's own stop is narrower does the DOE sit in front of the stop; its
diffraction over the gap is then propagated (``doefab.optics.gap``).
"""

from __future__ import annotations

import json
import math

import numpy as np
import torch

from doefab.optics.camera import STOP_TOLERANCE, Camera, require_camera
from doefab.optics.propagators import make_route
from doefab.optics.propagators.base import FocalSetup, plane_batches, scratch_kwargs
from doefab.optics.pupil import pupil_half, source_path_difference

__all__ = ["MountedPlan", "stop_case", "STOP_TOLERANCE"]


#: a sample the plain half covers less than this is off it (``MountedPlan.plain_key``): the exact area formula
#: leaves about 3e-17 on samples wholly across the split
PLAIN_COVER = 1e-9


def stop_case(camera: Camera) -> str:
    """One sentence for reports: which element is the aperture stop and what that means for the gap. Diameters
    within ``STOP_TOLERANCE`` of each other are called about equal; others are printed with the decimals that
    tell them apart, so the words agree with the numbers shown."""
    doe, lens = camera.aperture_diameter * 1e3, camera.lens_pupil_diameter * 1e3
    a, b = _distinct(doe, lens)
    pupil = f"the lens's {b} mm entrance pupil (f/{camera.lens_f_number:g})"
    doe_stop = "the dual-pixel split is conjugate to the DOE, and the DOE-to-lens gap moves nothing"
    lens_stop = "the DOE sits in front of it, and its diffraction over the gap is propagated"
    if abs(doe - lens) <= STOP_TOLERANCE * max(doe, lens):
        return (f"the DOE's {a} mm baffle and {pupil} are about equal (within {STOP_TOLERANCE * 100:g} %): neither "
                f"is clearly the stop; the model takes the {'baffle' if camera.doe_is_stop else 'lens'} as the aperture "
                f"stop: {doe_stop if camera.doe_is_stop else lens_stop}")
    if camera.doe_is_stop:
        return f"the DOE's {a} mm baffle is narrower than {pupil}: it is the aperture stop, {doe_stop}"
    return (f"{pupil} is narrower than the DOE's {a} mm baffle: the lens is the stop, {lens_stop}; the model still "
            f"bounds the light by the baffle, which a scene and a checked PSFPlan refuse beyond "
            f"{STOP_TOLERANCE * 100:g} % (Camera.lens_cuts_doe)")


def _distinct(x: float, y: float) -> tuple[str, str]:
    """``x`` and ``y`` with two decimals, or more (up to six) where two would print different numbers alike; two
    for numbers alike to six decimals (a lens pupil equal to the baffle)."""
    for decimals in range(2, 7):
        a, b = f"{x:.{decimals}f}", f"{y:.{decimals}f}"
        if a != b:
            return a, b
    return f"{x:.2f}", f"{y:.2f}"


class MountedPlan:
    """Precomputed PSF model of mounted parts of one design grid (``camera``: the simulation grid's camera).

    ``psfs(field, decenter, gap)`` → {half: (n_depths, n_wavelengths, K, K)} energy fractions of the whole
    aperture, with ``field(i)`` the relief's complex transmittance at wavelength i on the window
    ``self.window`` (rows, cols) of the grid, relative to the plain glass (heights above the unetched level:
    ``relief.pattern_heights(...) − (L − 1)·d``). Its tensors and the PSFs live on ``device`` (a ``torch.device``,
    default the CPU).
    """

    def __init__(self, camera: Camera, wavelengths, depths, kernel: int, halves=("coded",), margin: float = 0.0,
                 route: str = "spectral", device=None):
        from doefab._devices import to_device

        self.device = torch.device("cpu") if device is None else torch.device(device)
        self.camera = require_camera(camera, "MountedPlan camera")
        self.wavelengths, self.depths = tuple(wavelengths), tuple(depths)
        self.kernel, self.halves, self.margin = int(kernel), tuple(halves), float(margin)
        self.route = make_route(route)
        self._k = [2 * math.pi / lam for lam in self.wavelengths]
        self._dn = [float(camera.material.index(lam)) - 1.0 for lam in self.wavelengths]
        self.geo, self._prepared = {}, {}
        for half in self.halves:
            geo = pupil_half(camera, half, 1, 0.0, self.margin)
            setup = FocalSetup(geo.x, geo.y, geo.pitch, half == "coded", self.wavelengths, camera.sensor_distance,
                               camera.sensor_pitch, self.kernel, (0.0, 0.0), torch.float32, None)
            self.route.check(setup)
            self.geo[half] = geo
            self._prepared[half] = (setup, to_device(self.route.prepare(setup), self.device))
        rows = [g.rows for g in self.geo.values()]
        cols = [g.cols for g in self.geo.values()]
        self.window = ((min(r.start for r in rows), max(r.stop for r in rows)),
                       (min(c.start for c in cols), max(c.stop for c in cols)))
        self._cov: dict = {}

    def phase_per_metre(self, i: int) -> float:
        """k·Δn at wavelength i: the phase a metre of relief adds (radians per metre)."""
        return self._k[i] * self._dn[i]

    def covers(self, decenter) -> bool:
        return abs(float(decenter[0])) <= self.margin

    def plain_key(self, field, decenter=(0.0, 0.0), gap: float = 0.0) -> str | None:
        """The key a part's plain-half PSF is kept under (``PSFJudge.reuse``) when its transmittance ``field(i)``
        (as ``psfs`` takes it; this plan holds the plain half) is exactly 1 wherever the half covers more than
        ``PLAIN_COVER`` of a sample and no gap is propagated (a gap behind a DOE that is the stop moves nothing):
        that PSF is then the same for every part with the same decenter (m), to float32 rounding (a sample covered
        less moves it by 1e-9 of one sample's light at most) — the tornado's relief errors and the quantization
        study's levels share the error-free part's; else None."""
        if self.propagates(gap):  # the gap spreads the coded relief into the half
            return None
        dx = float(decenter[0])
        cover = self.coverage("uncoded", dx) > PLAIN_COVER
        (r0, r1), (c0, _) = self.window
        g = self.geo["uncoded"]
        rows, cols = slice(g.rows.start - r0, g.rows.stop - r0), slice(g.cols.start - c0, g.cols.stop - c0)
        if not all(bool((field(i).reshape(r1 - r0, -1)[rows, cols].to(cover.device)[cover] == 1).all())
                   for i in range(len(self.wavelengths))):
            return None
        return "plain half " + json.dumps([dx, float(decenter[1]), self.margin, self.kernel])  # no gap: none moves

    def propagates(self, gap: float) -> bool:
        """Whether a gap of ``gap`` metres between the DOE and the lens is propagated: only in front of a lens stop
        (module docstring)."""
        return gap > 0 and not self.camera.doe_is_stop

    def coverage(self, half: str, dx: float) -> torch.Tensor:
        """[rows, cols] of ``half``'s window (``self.geo[half]``): the fraction of each sample on the half's side
        of the split line, the die ``dx`` metres across it (on the plan's device)."""
        key = (half, round(dx, 15))
        if key not in self._cov:
            geo = pupil_half(self.camera, half, 1, -dx, self.margin)
            self._cov[key] = torch.from_numpy(geo.coverage).to(self.device, torch.float32)
            if len(self._cov) > 8:
                self._cov.pop(next(iter(self._cov)))
        return self._cov[key]

    def psfs(self, field, decenter=(0.0, 0.0), gap: float = 0.0, halves=None) -> dict:
        """PSFs of the part whose relief transmittance is ``field(i)`` ([rows × cols] of ``self.window``, complex)
        and whose die centre sits ``decenter`` = (dx, dy) metres from the lens axis (x across the split)."""
        dx, dy = float(decenter[0]), float(decenter[1])
        halves = self.halves if halves is None else tuple(halves)
        (r0, r1), (c0, c1) = self.window
        propagate = self.propagates(gap)
        out = {h: [] for h in halves}
        opd = {h: self._opd(h, dx, dy) for h in halves}
        d = len(self.depths)
        # the route's working buffers, reused by every wavelength and plane batch of this part (a route of the user's
        # own that takes no ``scratch`` gets none)
        kw = scratch_kwargs(self.route)
        for i in range(len(self.wavelengths)):
            t = field(i).reshape(r1 - r0, c1 - c0).to(self.device)
            t = torch.stack([self._through_gap(t, i, j, gap) for j in range(d)]) if propagate else t[None]
            for half in halves:
                geo = self.geo[half]
                sub = t[:, geo.rows.start - r0:geo.rows.stop - r0, geo.cols.start - c0:geo.cols.stop - c0]
                setup, prepared = self._prepared[half]
                planes = d if (opd[half] is not None or propagate) else 1
                got = []
                for b in plane_batches(planes, 4 * sub.shape[-1] * sub.shape[-2]):  # pupils of a few planes
                    pupil = self.coverage(half, dx) * (sub if sub.shape[0] == 1 else sub[b])
                    if opd[half] is not None:
                        pupil = pupil * torch.polar(torch.ones_like(opd[half][b]), self._k[i] * opd[half][b])
                    got.append(self.route.intensity(pupil, i, setup, prepared, **kw))
                inten = (got[0] if len(got) == 1 else torch.cat(got)) / geo.full_area
                out[half].append(inten.expand(d, self.kernel, self.kernel))
        return {h: torch.stack(v, dim=1) for h, v in out.items()}

    def _opd(self, half: str, dx: float, dy: float):
        """[D, rows, cols] the source's optical path relative to the plane in focus, at lens-frame radii, or None
        when every depth is the focus distance (a plane of zeros)."""
        if all(z == self.camera.focus_distance for z in self.depths):
            return None
        geo = self.geo[half]
        r2 = (geo.y[:, None] + dy) ** 2 + (geo.x[None, :] + dx) ** 2
        return torch.from_numpy(np.stack([source_path_difference(r2, z, self.camera.focus_distance)
                                          for z in self.depths])).to(self.device, torch.float32)

    def _through_gap(self, t: torch.Tensor, i: int, j: int, gap: float) -> torch.Tensor:
        """The window's transmittance carried over the gap to the lens's stop for the source at depth j
        (lens-limited case only; ``t`` is relative to the plain glass, which is 1 outside the window)."""
        from doefab.optics.gap import gap_field

        n = self.camera.doe_pixels
        (r0, r1), (c0, c1) = self.window
        full = torch.ones((n, n), dtype=torch.complex64, device=t.device)
        full[r0:r1, c0:c1] = t
        return gap_field(full, self.camera, self.wavelengths[i], self.depths[j], gap)[r0:r1, c0:c1]
