"""Coded and uncoded captures of a scene through a PSF pair (the paper's Eq. 11, 14, 23, 27).

Each half's PSF carries half of the aperture's light (the PSFs are fractions of the whole aperture), so each
capture is a half-exposure image: a uniform scene of radiance 1 gives about 0.5 in each capture.

- RGB scenes (C = 3, ``response=None``): channel c is convolved with the PSF of wavelength c.
- Spectral scenes (``response`` [3, C]): every band is convolved with its own PSF, then the sensor's RGB
  response sums the bands (Eq. 23).
- Depth scenes (``depth_map``): the scene is split into the PSF's depth planes (nearest plane per pixel,
  Eq. 27) and the layers are composited back to front *with occlusion*: each nearer layer's blurred mask
  attenuates what lies behind it (``acc ← acc · (1 − p∗M_z) + p∗(I·M_z)``), so a near object hides the far one
  instead of adding to it as Eq. 27's plain sum does.
- Then clip to [0, 1] after noise (``sensor.noise_model``); the random generator is seeded.
- The captures are :class:`Capture` arrays: numpy arrays that also name the PSF pair they were recorded
  through (``capture.pair``; a torch tensor carries the same attribute), so a reconstructor can refuse captures
  of other bands or another camera than its own (``reconstruction.loader``).

Convolutions are linear (zero-padded FFT, 'same' crop), batched over bands in torch, on the ``device`` asked for
(the CPU or a GPU); the noise and the crosstalk are drawn on the CPU from the seeded generator, so a seed gives the
same noise on every device.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from doefab import validate as _validate
from doefab._devices import resolve_device
from doefab.errors import DoefabError
from doefab.imaging.crosstalk import DualPixelCrosstalk, check_pair
from doefab.imaging.sensor import noise_model

__all__ = ["simulate_captures", "convolve", "convolve_valid", "render_layers", "plane_masks", "fft_length",
           "irfft2_crop", "Capture", "MAX_RADIANCE"]

#: The brightest scene radiance ``simulate_captures`` takes, in units of the clipping level of a full exposure:
#: a million times it (20 stops above; the HDR scenes here peak at 60×, the sun's disc against a sunlit scene is
#: about 5e4×). Brighter light saturates every pixel a PSF's 1e-6 tail reaches, and its shot noise overflows the
#: Poisson sampler.
MAX_RADIANCE = 1e6
#: Above this peak radiance the captures are convolved in float64: float32's FFT rounding spreads about 2e-9 of the
#: brightest point over the whole frame (2e-4 of full scale at 1e5 and 1.5e-3 at 1e6, where no PSF reaches;
#: ``tests/imaging/test_bright_scenes.py``), below 1e-6 of full scale only up to here (2⁸, the training scenes' top)
FLOAT32_RADIANCE = 256.0


class Capture(np.ndarray):
    """A simulated capture: a numpy array that also names the ``PSFPair`` it was recorded through (``pair``).
    Views, crops and arithmetic keep it; a reduction to one number is a plain numpy scalar; ``np.asarray``
    gives the plain array."""

    pair = None

    def __array_finalize__(self, obj):
        self.pair = getattr(obj, "pair", None)

    def __array_wrap__(self, arr, context=None, return_scalar=False):  # numpy ≥ 2 passes return_scalar
        if arr.ndim == 0:
            return arr[()]
        return super().__array_wrap__(arr, context)


def fft_length(n: int) -> int:
    """The smallest even 5-smooth length ≥ ``n`` (2^a·3^b·5^c, a ≥ 1): any length ≥ h + k − 1 gives the same
    linear convolution, and real transforms of these lengths are the fastest (an odd one such as 625 is slower
    than 640 in torch's CPU FFT)."""
    from scipy.fft import next_fast_len

    m = next_fast_len(int(n), real=True)
    while m % 2:
        m = next_fast_len(m + 1, real=True)
    return m


def irfft2_crop(spec: torch.Tensor, s: tuple[int, int], rows: slice, cols: slice) -> torch.Tensor:
    """``torch.fft.irfft2(spec, s=s)[..., rows, cols]``, with the rows cropped between the two passes: the column
    pass's inverse FFT (along rows) runs in full, the real inverse FFT along each row only on the rows kept. The
    same numbers to rounding, and bit for bit on x86 CPU builds with MKL (their two-dimensional inverse is these
    two passes, each scaled by its own length; pocketfft builds and CUDA scale once: rounding-level differences);
    a frame cropped from a padded FFT canvas costs a row pass less per row cropped away. ``s`` and the slices in
    pixels.

    Example: ``irfft2_crop(torch.fft.rfft2(x), x.shape[-2:], slice(8, 72), slice(8, 72))`` for [..., 80, 80] ``x``."""
    t = torch.fft.ifft(spec, n=s[0], dim=-2)[..., rows, :]
    return torch.fft.irfft(t, n=s[1], dim=-1)[..., cols]


def convolve(images: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Linear 'same' convolution of [..., C, H, W] images with [C, K, K] PSFs (pixel K//2 at the centre)."""
    h, w = images.shape[-2:]
    k = psf.shape[-1]
    fh, fw = fft_length(h + k - 1), fft_length(w + k - 1)
    spec = torch.fft.rfft2(images, s=(fh, fw)) * torch.fft.rfft2(psf.to(images.dtype), s=(fh, fw))
    c = k // 2
    return irfft2_crop(spec, (fh, fw), slice(c, c + h), slice(c, c + w))


def convolve_valid(images: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
    """Linear 'valid' convolution of [..., C, H, W] images with [C, K, K] PSFs: [..., C, H − K + 1, W − K + 1],
    the pixels whose every contributing image pixel lies in the frame. A frame padded by (K − 1) // 2 before and
    K // 2 after comes back at its own size, as :func:`convolve` gives it (PSF pixel K // 2 at the centre). The
    FFT canvas needs only the frame's length: the wrapped light lands outside the output.

    Example: ``convolve_valid(F.pad(img, (7, 7, 7, 7), mode="replicate"), psf)`` with [3, 15, 15] ``psf``."""
    h, w = images.shape[-2:]
    k_h, k_w = psf.shape[-2:]
    if k_h > h or k_w > w:
        raise DoefabError(f"a valid convolution needs a frame at least as large as the PSF: {h}×{w} < {k_h}×{k_w}")
    fh, fw = fft_length(h), fft_length(w)
    spec = torch.fft.rfft2(images, s=(fh, fw)) * torch.fft.rfft2(psf.to(images.dtype), s=(fh, fw))
    return irfft2_crop(spec, (fh, fw), slice(k_h - 1, h), slice(k_w - 1, w))


def render_layers(scene: torch.Tensor, psf: torch.Tensor, masks: torch.Tensor | None = None,
                  depths=None) -> torch.Tensor:
    """Blurred scene before noise.

    Args:
        scene: [..., C, H, W] radiance.  psf: [D, C, K, K] (one PSF per depth plane and band).
        masks: [D, H, W] 0/1 membership of each pixel in each depth plane, or None for a single plane (D = 1).
        depths: the planes' depths in metres (to composite from the farthest to the nearest).
    """
    if masks is None:
        return convolve(scene, psf[0])
    # farthest plane first: ascending inverse depth (plane index order when no depths are given)
    order = sorted(range(psf.shape[0]), key=(lambda d: 1.0 / depths[d]) if depths else (lambda d: d))
    h, w = scene.shape[-2:]
    k = psf.shape[-1]
    fh, fw = fft_length(h + k - 1), fft_length(w + k - 1)
    c = k // 2
    acc = torch.zeros_like(scene)
    for d in order:  # farthest first
        m = masks[d].to(scene.dtype)
        if not bool(m.any()):
            continue
        # one transform of the PSFs serves the layer and (normalised) its cover; the mask is transformed once
        p = psf[d].to(scene.dtype)
        pf = torch.fft.rfft2(p, s=(fh, fw))
        layer = torch.fft.rfft2(scene * m, s=(fh, fw)) * pf
        cover = torch.fft.rfft2(m, s=(fh, fw)) * pf / p.sum(dim=(-2, -1))[:, None, None].clamp_min(1e-30)
        spec = torch.cat([layer, cover.expand(layer.shape)], dim=-3)
        both = irfft2_crop(spec, (fh, fw), slice(c, c + h), slice(c, c + w))
        n = p.shape[0]
        acc = acc * (1 - both[..., n:, :, :].clamp(0, 1)) + both[..., :n, :, :]
    return acc


def plane_masks(depth_map: torch.Tensor, depths) -> torch.Tensor:
    """[D, H, W] one-hot: each pixel in the plane nearest in inverse depth (dioptres; ``inf`` allowed), on the
    depth map's device."""
    inv = torch.tensor([0.0 if math.isinf(z) else 1.0 / z for z in depths], dtype=torch.float64,
                       device=depth_map.device)
    idx = torch.argmin((1.0 / depth_map.double()[None] - inv[:, None, None]).abs(), dim=0)
    return torch.stack([idx == d for d in range(len(depths))]).to(torch.float32)


def simulate_captures(scene, pair, depth_map=None, response=None, noise="default", seed: int = 0, crosstalk=None,
                      device=None):
    """``(coded, uncoded)`` captures: two [3, H, W] float32 arrays in [0, 1] (numpy in, numpy out; torch in,
    torch out, on the CPU).

    Args:
        scene: [C, H, W] linear radiance ≥ 0, C = the pair's wavelengths.
        pair: a :class:`doefab.PSFPair` with both halves.
        depth_map: [H, W] metres (> 0, within the pair's nearest and farthest planes) to split the scene into the
            pair's depth planes (with occlusion);
            None for a pair of one depth.
        response: [3, C] RGB response for spectral scenes (``doefab.sensor_response(pair.wavelengths)``);
            None for RGB scenes (C = 3).
        noise: ``"default"`` (Poisson–Gaussian), ``"authors"`` (uniform ±0.01), ``"none"``, a model, or a
            ``doefab.Sensor`` (its full well and read noise; its ``rgb(pair.wavelengths)`` is the response).
        seed: seeds the noise (coded first, then uncoded).
        crosstalk: None (each view records only its own half), or a ``doefab.imaging.crosstalk.DualPixelCrosstalk``
            — the camera's per-column ratios mix the two views (Eq. 29) before the noise, and, when it carries a
            calibration's estimate, its pipeline unmixes them after (the captures a user's pipeline delivers).
            A ``(α_l→r, α_r→l)`` pair mixes without unmixing.
        device: where the scene is blurred ("auto", "cpu", "cuda", "cuda:N"; None: the current default,
            ``doefab._devices.default_device``); the captures come back to the CPU.

    Example:
        A flat grey scene through a blank DOE, without noise: both views see half the light.

        >>> import numpy as np, doefab
        >>> cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
        >>> pair = doefab.split_aperture_psf(None, cam, [656e-9, 589e-9, 486e-9], [float("inf")], kernel_size=21)
        >>> coded, uncoded = doefab.simulate_captures(np.full((3, 64, 64), 0.5, np.float32), pair, noise="none")
        >>> coded.shape, bool(np.allclose(coded[:, 32, 32], uncoded[:, 32, 32], atol=1e-3))
        ((3, 64, 64), True)
    """
    torch_in = isinstance(scene, torch.Tensor)
    dev = resolve_device(device)
    seed = _validate.seed("seed", seed)
    s = _finite("scene", scene, 3)
    if bool((s < 0).any()):
        raise DoefabError(f"scene holds negative radiance (min {float(s.min()):g}): radiance is ≥ 0 (linear, not "
                          f"log or centred)")
    top = float(s.max()) if s.numel() else 0.0
    if top > MAX_RADIANCE:
        raise DoefabError(f"scene holds radiance up to {top:.3g}: simulate_captures takes radiance up to "
                          f"{MAX_RADIANCE:g} times the clipping level of a full exposure (1); scale the scene, e.g. "
                          f"multiply it by {100 / top:.3g} to put its brightest point at 100")
    dtype = torch.float64 if top > FLOAT32_RADIANCE else torch.float32
    s = s.to(dev, dtype)
    if pair.coded is None or pair.uncoded is None:
        raise DoefabError("the PSF pair lacks a half: compute it with halves=('coded', 'uncoded')")
    c, h, w = s.shape
    lams = tuple(pair.wavelengths)
    if c != len(lams):
        raise DoefabError(f"the scene has {c} bands but the PSF pair {len(lams)} wavelengths "
                          f"({', '.join(f'{x * 1e9:.0f}' for x in lams[:6])}{'…' if len(lams) > 6 else ''} nm): "
                          f"compute the pair for the scene's bands")
    t = _response(response, c, top)
    masks = None if depth_map is None else _depth_masks(depth_map, pair, (h, w), dev)
    if depth_map is None and len(pair.depths) != 1:
        raise DoefabError(f"the PSF pair has {len(pair.depths)} depth planes: pass depth_map (metres) or a pair "
                          f"computed for one depth")
    noise_obj = noise_model(noise)
    rng = np.random.default_rng(seed)
    views = []
    with torch.no_grad():
        for half in ("coded", "uncoded"):
            psf = pair[half].detach().to(dev, dtype)
            blurred = render_layers(s, psf, masks, pair.depths)
            rgb = torch.einsum("rc,chw->rhw", t.to(dev, dtype), blurred) if t is not None else blurred
            views.append(rgb.double().cpu().numpy())
    out = [v.astype(np.float32) for v in _camera(crosstalk).record(views[0], views[1], noise_obj, rng)]
    return _labelled(out[0], pair, torch_in), _labelled(out[1], pair, torch_in)


def _depth_masks(depth_map, pair, shape: tuple, dev) -> torch.Tensor:
    """The per-plane masks of ``depth_map`` (metres, ``shape``), refused unless it holds depths > 0 within the
    pair's planes (beyond them no PSF says how the scene blurs)."""
    dm = _check_array("depth_map", depth_map, 2)
    if tuple(dm.shape) != shape:
        raise DoefabError(f"depth_map has shape {tuple(dm.shape)}, the scene {shape}")
    if bool((dm <= 0).any()):
        raise DoefabError("depth_map must hold depths > 0 in metres")
    near, far = min(pair.depths), max(pair.depths)
    lo, hi = float(dm.min()), float(dm.max())
    if len(pair.depths) > 1 and (lo < near * (1 - 1e-6) or hi > far * (1 + 1e-6)):
        raise DoefabError(f"depth_map spans {lo:.4g}–{hi:.4g} m, beyond the PSF pair's planes ({near:.4g}–{far:.4g} "
                          f"m), where no PSF says how the scene blurs: clip it to the planes "
                          f"(depth_map.clip({near:.4g}, {far:.4g})) or compute the pair for planes that span it "
                          f"(depths are in metres)")
    return plane_masks(dm.to(dev), pair.depths)


def _response(response, c: int, top: float) -> torch.Tensor | None:
    """The [3, C] response as float32 (None for an RGB scene), checked against a scene peaking at ``top``: the
    RGB radiance it forms stays within ``MAX_RADIANCE``."""
    if response is None:
        if c != 3:
            raise DoefabError(f"a {c}-band scene needs response=sensor_response(pair.wavelengths) to form RGB "
                              f"captures")
        return None
    t = _check_array("response", response, 2)
    if tuple(t.shape) != (3, c) or bool((t < 0).any()):
        raise DoefabError(f"response must be a non-negative [3, {c}] array (RGB × bands), got {tuple(t.shape)}")
    gain = float(t.double().sum(dim=1).max())
    if gain * top > MAX_RADIANCE:
        raise DoefabError(f"response sums to {gain:.3g} over the bands in its largest channel: with the scene's peak "
                          f"{top:.3g} the RGB radiance would reach {gain * top:.3g}, beyond {MAX_RADIANCE:g}; use a "
                          f"normalised response (doefab.sensor_response sums to 1 in its most sensitive channel)")
    return t


def _labelled(view: np.ndarray, pair, torch_in: bool):
    """``view`` as a :class:`Capture` of ``pair`` (a torch tensor with a ``pair`` attribute when ``torch_in``)."""
    if torch_in:
        t = torch.from_numpy(view)
        t.pair = pair
        return t
    out = view.view(Capture)
    out.pair = pair
    return out


def _camera(crosstalk):
    if crosstalk is None:
        return DualPixelCrosstalk(0.0, 0.0)
    if isinstance(crosstalk, DualPixelCrosstalk):
        return crosstalk
    try:
        a, b = crosstalk
    except (TypeError, ValueError):
        raise DoefabError("crosstalk must be a DualPixelCrosstalk or an (α_l→r, α_r→l) pair of fractions") from None
    check_pair(a, b, "crosstalk α_l→r, α_r→l")
    return DualPixelCrosstalk(a, b)


def _finite(name: str, x, ndim: int) -> torch.Tensor:
    """``x`` as a tensor of its own precision with ``ndim`` dimensions, every value finite."""
    t = torch.as_tensor(x.detach() if isinstance(x, torch.Tensor) else np.asarray(x))
    if t.ndim != ndim:
        raise DoefabError(f"{name} must have {ndim} dimensions, got shape {tuple(t.shape)}")
    if t.is_complex():
        raise DoefabError(f"{name} must hold real numbers, got dtype {t.dtype}")
    if not bool(torch.isfinite(t).all()):
        raise DoefabError(f"{name} contains NaN or infinite values: every value must be finite")
    return t


def _check_array(name: str, x, ndim: int) -> torch.Tensor:
    """``x`` as float32 (``_finite``), its values within float32's range."""
    t = _finite(name, x, ndim)
    big, top = (float(t.abs().max()) if t.numel() else 0.0), torch.finfo(torch.float32).max
    if big > top:
        raise DoefabError(f"{name} holds values up to {big:.3g}, beyond float32's {top:.3g}: give it in the "
                          f"units simulate_captures documents")
    return t.to(torch.float32)
