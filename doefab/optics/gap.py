"""A DOE mounted a distance in front of the aperture plane (the prototype's add-on holder, the paper's Fig. 4).

The paper designs the DOE for the aperture plane, but the prototype's holder puts it against the lens's front
glass, some millimetres in front of the plane where the dual-pixel sensor splits the pupil. Over that gap the
DOE's diffraction spreads: coded light crosses the split line into the uncoded half and the coded half's
pattern blurs at its edges. ``gap_transmittance`` gives the DOE's effective complex transmittance *at the
aperture plane*:

    t_eff = 1 + ASM_g[ S_z · circ · (exp(i k Δn (h − h_ref)) − 1) ] / S_{z+g}

with ``S_z`` the exact spherical wave of the on-axis point at depth z arriving at the DOE (plane wave for
z = ∞), ``circ`` the DOE's chrome baffle (the clear aperture), ``h_ref`` the mean height of the plain (x > 0)
half so that the plain glass is the phase reference, ``ASM_g`` the band-limited angular spectrum over the gap g
(``doefab.angular_spectrum``, zero-padded: the modulation is confined to the baffle so the padding is exact)
and ``S_{z+g} = z / (z + g) · exp(i k (sag(z + g) + g))`` the unmodulated wave at the aperture plane (paraxial
amplitude). Writing the field as the plain wave plus the DOE's *change* keeps the plain wave analytic, so a
blank DOE or g = 0 gives t_eff = exp(i k Δn (h − h_ref)) exactly, and the only numerical propagation is of the
DOE's modulation. Valid while the incoming wave's curvature is resolved at the DOE pitch (it is, far beyond the
depths doefab's PSFs allow) and the gap is a free-space path (no lens element between DOE and aperture plane —
in a real compound lens the front elements refract the cone slightly; the model treats the gap as air).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

from doefab.validate import depths, wavelength_m
from doefab.errors import DoefabError
from doefab.optics.camera import Camera, require_camera
from doefab.optics.elements import as_height_tensor
from doefab.optics.propagators.asm import angular_spectrum
from doefab.optics.pupil import pupil_half, source_path_difference

__all__ = ["gap_transmittance", "gap_field", "MAX_GAP", "check_gap"]

MAX_GAP = 0.05  # metres: beyond this the DOE is not "in front of the aperture" but a separate element


def check_gap(gap: float) -> float:
    """``gap`` in metres, checked to lie within 0 – MAX_GAP."""
    g = float(gap)
    if not math.isfinite(g) or not 0.0 <= g <= MAX_GAP:
        raise DoefabError(f"DOE gap {gap!r} m is outside 0–{MAX_GAP} m (the gap is in metres: 2 mm is 2e-3)")
    return g


@functools.lru_cache(maxsize=4)
def _baffle(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(baffle opening, plain-half pixels inside it, squared radius) on the DOE grid: fixed per camera, so
    computed once rather than for every wavelength, depth and sampled part."""
    n = camera.doe_pixels
    full = pupil_half(camera, "full")
    circ = np.zeros((n, n))
    circ[full.rows, full.cols] = full.coverage > 0  # the baffle opening: every pixel the clear aperture touches
    centres = (np.arange(n) - (n - 1) / 2) * camera.doe_pitch
    plain = (centres > 0)[None, :] & (circ > 0)
    return circ, plain, centres[None, :] ** 2 + centres[:, None] ** 2


def gap_transmittance(height: torch.Tensor, camera: Camera, wavelength: float, depth: float, gap: float,
                      pad: float | None = None) -> torch.Tensor:
    """(N, N) complex effective transmittance at the aperture plane of a DOE ``gap`` metres in front of it.

    Args:
        height: (N, N) heights in metres on the camera's DOE grid (both halves: the plain half is the
            phase reference; a tensor or array, validated by ``elements.as_height_tensor``).
        wavelength: metres.  depth: on-axis source distance in metres (``inf`` = plane wave).
        gap: DOE-to-aperture-plane distance, metres (0 ≤ gap ≤ 5 cm).
        pad: zero-padding factor of the angular spectrum grid. Default: just enough that light diffracted at
            the grid's largest angle (sin θ = λ / 2b, b the DOE pitch) over the gap cannot wrap around into the
            grid (linear, not circular, convolution), plus 16 pixels.

    Example:

        >>> import numpy as np, doefab
        >>> cam = doefab.Camera(doe_pixels=64, doe_pitch=135e-6)
        >>> t = doefab.gap_transmittance(np.zeros((64, 64)), cam, 550e-9, float("inf"), 1e-3)  # a blank DOE 1 mm out
        >>> tuple(t.shape), round(float(abs(t[32, 32])), 3)  # a plane wave crosses it unchanged
        ((64, 64), 1.0)
    """
    camera, g = require_camera(camera), check_gap(gap)
    wavelength = wavelength_m("wavelength", wavelength)
    depth = depths([depth])[0]
    keep = isinstance(height, torch.Tensor) and height.is_floating_point()  # its dtype (and graph) kept
    h = as_height_tensor(height, camera, "height", height.dtype if keep else torch.float64)
    k = 2 * math.pi / wavelength
    dn = float(camera.material.index(wavelength)) - 1.0
    _, plain, _ = _baffle(camera)
    h_ref = h[torch.from_numpy(plain).to(h.device)].mean() if plain.any() else h.new_zeros(())
    phase = (k * dn) * (h - h_ref)
    return gap_field(torch.polar(torch.ones_like(phase), phase), camera, wavelength, depth, g, pad)


def gap_field(relative: torch.Tensor, camera: Camera, wavelength: float, depth: float, gap: float,
              pad: float | None = None) -> torch.Tensor:
    """(N, N) complex effective transmittance at the aperture plane of a DOE whose own complex transmittance,
    relative to the plain glass, is ``relative`` (on the camera's DOE grid), ``gap`` metres in front of it
    (see :func:`gap_transmittance`, which builds ``relative`` from heights)."""
    g = check_gap(gap)
    n = camera.doe_pixels
    if tuple(relative.shape) != (n, n) or not relative.is_complex():
        raise DoefabError(f"relative transmittance must be complex ({n}, {n}), got {tuple(relative.shape)}")
    if g == 0.0:
        return relative
    cplx = relative.dtype
    real = torch.float32 if cplx == torch.complex64 else torch.float64
    k = 2 * math.pi / wavelength
    circ, _, r2 = _baffle(camera)
    s_in = source_path_difference(r2, depth, math.inf)  # exact sphere sag of the source at the DOE
    s_out = source_path_difference(r2, depth + g if math.isfinite(depth) else depth, math.inf)
    amp = depth / (depth + g) if math.isfinite(depth) else 1.0
    wave_in = torch.from_numpy(np.exp(1j * k * s_in)).to(relative.device, cplx)
    # the plain wave at the aperture plane, with the angular spectrum's own piston exp(i k g)
    wave_out = torch.from_numpy(amp * np.exp(1j * k * (s_out + g))).to(relative.device, cplx)
    change = (relative - 1) * torch.from_numpy(circ).to(relative.device, real)
    if pad is None:
        sin_max = min(wavelength / (2 * camera.doe_pitch), 0.99)
        spread_px = g * sin_max / math.sqrt(1 - sin_max**2) / camera.doe_pitch
        pad = 1.0 + (spread_px + 16) / n
    moved = angular_spectrum(wave_in * change, camera.doe_pitch, wavelength, g, pad=pad)
    return 1 + moved / wave_out
