"""G_HS: 31-band spectra from the coded (grating) and the uncoded capture.

The network predicts a residual (zero-initialised head) over a linear spectral estimate from one capture:

- ``proposed``: the smooth inverse of the uncoded capture under the library's illuminants, mixed with the
  non-negative weights whose predicted coded capture, through the dispersing PSFs, matches the measured one best
  (``illuminant.mix_illuminants``: RGB cannot tell a spiky lamp from a smooth one of the same colour, the
  grating's dispersion can; a light the library lacks is met by a blend, not forced onto one wrong member —
  chosen on validation scenes, ``benchmarks/illuminant_search.py``). Networks recorded without ``illuminant_mix``
  use the single best member (``illuminant.search_illuminant``);
- ``uncoded_only``: one smooth inverse of the sensor response applied to the uncoded capture;
- ``coded_only``: the same inverse applied to the coded capture *where each band's light landed*: the grating
  moves band λ's image to its first order, so band λ's estimate reads the capture shifted back by that offset
  (the peak of the PSF given at call time) — an ablation removes the uncoded capture, it does not misalign the
  coded one.

The coded capture's learned features are Wiener-deconvolved with every band's PSF (``CodedFeatures``), the
uncoded capture's features join them, and a small U-Net decodes. ``psf``: the coded PSF per band,
[B or 1, C, K, K].
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from doefab.errors import DoefabError
from doefab.reconstruction.illuminant import mix_illuminants, search_illuminant
from doefab.reconstruction.networks import CodedFeatures, UNet, check_input, check_psf, views_of

__all__ = ["SpectralNet", "default_arch", "build", "loss", "arch_response", "spectral_baseline", "dispersion_offsets",
           "register_bands"]


def dispersion_offsets(psf: torch.Tensor) -> torch.Tensor:
    """[C, 2] (rows, columns) of each band's PSF peak from the window's centre: where its light lands."""
    c, k = psf.shape[0], psf.shape[-1]
    flat = psf.reshape(c, -1).argmax(dim=1)
    return torch.stack([flat // k - k // 2, flat % k - k // 2], dim=1)


def register_bands(capture: torch.Tensor, weights: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """[B, C, H, W]: band λ = Σ_k weights[λ, k] · capture_k read at (x + offset_λ) (edges replicated)."""
    b, _, h, w = capture.shape
    m = int(offsets.abs().max()) if offsets.numel() else 0
    pad = F.pad(capture, (m, m, m, m), mode="replicate")
    out = []
    for lam in range(weights.shape[0]):
        dy, dx = int(offsets[lam, 0]), int(offsets[lam, 1])
        view = pad[:, :, m + dy:m + dy + h, m + dx:m + dx + w]
        out.append(torch.einsum("k,bkhw->bhw", weights[lam], view))
    return torch.stack(out, dim=1)


def default_arch(variant: str = "proposed") -> dict:
    """The shipped hyperspectral networks' architecture record: 2 coded features, U-Net width 16; the proposed
    network searches the illuminant library and mixes its members (``illuminant.mix_illuminants``)."""
    return {"features": 2, "width": 16, "illuminant_search": variant == "proposed",
            "illuminant_mix": variant == "proposed"}


def build(variant: str, arch: dict) -> nn.Module:
    """The hyperspectral network of ``variant`` from its architecture record: on the record's bands (default the
    31 of 400–700 nm) and response (default the default camera's); records without ``illuminant_mix`` use the
    single best member of the library."""
    from doefab.reconstruction.data import HS_WAVELENGTHS_M

    bands = tuple(arch.get("wavelengths_m") or HS_WAVELENGTHS_M)
    t = arch_response(arch, bands)
    return SpectralNet(len(bands), variant, features=int(arch["features"]), width=int(arch["width"]),
                       baseline=spectral_baseline(bands, response=t),
                       illuminant=_illuminant_search(bands, t) if arch.get("illuminant_search") else None,
                       mix=bool(arch.get("illuminant_mix", False)))


def loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The hyperspectral training loss: L1."""
    return (pred - target).abs().mean()


def arch_response(arch: dict, bands):
    """The [3, C] sensor response a spectral network was built for: the record's own (``"response"``, written
    for a camera other than the default) or the default camera's on ``bands``."""
    import numpy as np

    from doefab.imaging.sensor import sensor_response

    if arch.get("response") is None:
        return sensor_response(bands)
    t = np.asarray(arch["response"], np.float32)
    if t.shape != (3, len(bands)) or not np.all(np.isfinite(t)) or np.any(t < 0):
        raise DoefabError(f"the architecture record's response must be a finite [3, {len(bands)}] array ≥ 0, got "
                          f"{t.shape}")
    return t


def _illuminant_search(bands, t):
    """(response [3, C], inverses [J, C, 3]) on ``bands`` for the proposed hyperspectral network's illuminant
    search (the shipped library resampled to them; ``t``: the response on the bands)."""
    from doefab.reconstruction.data import resample_bands
    from doefab.reconstruction.illuminant import illuminant_inverses, illuminant_library

    return t, illuminant_inverses(t, resample_bands(illuminant_library(), bands, axis=1))


def spectral_baseline(bands=None, smooth: float = 1e-3, eps: float = 1e-6, response=None):
    """[C, 3] smooth least-squares inverse of a half-exposure capture: s = argmin ‖½ T s − c‖² + μ‖D² s‖²
    (T: ``response`` [3, C], default the default camera's on ``bands``, default the 31 bands 400–700 nm; D²:
    second differences along wavelength) — the illuminant search's inverse under a flat illuminant."""
    import numpy as np

    from doefab.imaging.sensor import sensor_response
    from doefab.reconstruction.data import HS_WAVELENGTHS_M
    from doefab.reconstruction.illuminant import illuminant_inverses

    t = sensor_response(HS_WAVELENGTHS_M if bands is None else bands) if response is None else response
    return illuminant_inverses(t, np.ones((1, t.shape[1])), smooth, eps)[0]


class SpectralNet(nn.Module):
    def __init__(self, n_bands: int, variant: str = "proposed", features: int = 2, width: int = 16, baseline=None,
                 illuminant=None, mix: bool = False):
        super().__init__()
        self.views = views_of(variant)  # the captures this variant sees: its branches and its linear estimate
        if baseline is None:
            raise DoefabError("the spectral network needs its linear baseline [C, 3] (a smooth inverse)")
        self.variant, self.n_bands, self.mix = variant, int(n_bands), bool(mix)
        self.register_buffer("baseline", torch.as_tensor(baseline, dtype=torch.float32), persistent=False)
        # (response [3, C], inverses [J, C, 3]) of the proposed network's illuminant search
        self.register_buffer("response", None if illuminant is None else torch.as_tensor(illuminant[0]).float(),
                             persistent=False)
        self.register_buffer("inverses", None if illuminant is None else torch.as_tensor(illuminant[1]).float(),
                             persistent=False)
        # the linear estimate the residual is added to: the illuminant search (both captures), the coded capture
        # registered band by band (coded only), or the smooth inverse of the uncoded capture
        self.estimate = ("search" if len(self.views) == 2 and illuminant is not None else
                         "registered" if self.views == ("coded",) else "inverse")
        cin = 0
        self.coded = self.feat_uncoded = None  # a branch for each capture the variant sees
        if "coded" in self.views:
            self.coded = CodedFeatures(n_bands, features, raw=False)
            cin += self.coded.channels
        if "uncoded" in self.views:
            self.feat_uncoded = nn.Sequential(nn.Conv2d(3, 16, 3, padding=1), nn.LeakyReLU(0.1))
            cin += 16
        self.unet = UNet(cin, n_bands, width)
        nn.init.zeros_(self.unet.out.weight)  # start exactly at the baseline: zero residual head
        nn.init.zeros_(self.unet.out.bias)

    def forward(self, coded: torch.Tensor, uncoded: torch.Tensor, psf: torch.Tensor | None = None) -> torch.Tensor:
        parts = []
        if self.coded is not None:
            check_input(coded, "coded")
            psf = check_psf(psf, self.n_bands, "the coded PSF of every band")
            parts.append(self.coded(coded, psf))
        if self.feat_uncoded is not None:
            check_input(uncoded, "uncoded")
            parts.append(self.feat_uncoded(uncoded))
        y = self.unet(torch.cat(parts, dim=1)) + self._baseline(coded, uncoded, psf)
        return y if self.training else y.clamp_min(0.0)

    # [1, J] weights of the candidate lights fixed by the caller (None: estimated from each input): a tiled
    # reconstruction (doefab.lab.reconstruct) estimates a scene's light once, for all its tiles
    light = None

    def _baseline(self, coded, uncoded, psf) -> torch.Tensor:
        if self.estimate == "search":
            if self.light is not None:
                w = self.light.expand(uncoded.shape[0], -1)
                return torch.einsum("bj,joc,bchw->bohw", w, self.inverses, uncoded)
            if self.mix:
                w = mix_illuminants(coded, uncoded, psf[0], self.response, self.inverses)
                w = w / w.sum(dim=1, keepdim=True).clamp_min(1e-12)  # a blend of estimates, not a gain
                return torch.einsum("bj,joc,bchw->bohw", w, self.inverses, uncoded)
            idx, _ = search_illuminant(coded, uncoded, psf[0], self.response, self.inverses)
            return torch.einsum("boc,bchw->bohw", self.inverses[idx], uncoded)
        if self.estimate == "registered":
            return register_bands(coded, self.baseline, dispersion_offsets(psf[0]))
        return torch.einsum("oc,bchw->bohw", self.baseline, uncoded)
