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
from doefab.reconstruction.networks import VARIANTS, CodedFeatures, UNet, check_input, check_psf

__all__ = ["SpectralNet", "dispersion_offsets", "register_bands"]


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


class SpectralNet(nn.Module):
    def __init__(self, n_bands: int, variant: str = "proposed", features: int = 2, width: int = 16, baseline=None,
                 illuminant=None, mix: bool = False):
        super().__init__()
        if variant not in VARIANTS:
            raise DoefabError(f"variant must be one of {VARIANTS}, got {variant!r}")
        if baseline is None:
            raise DoefabError("the spectral network needs its linear baseline [C, 3] (a smooth inverse)")
        self.variant, self.n_bands, self.mix = variant, int(n_bands), bool(mix)
        self.register_buffer("baseline", torch.as_tensor(baseline, dtype=torch.float32), persistent=False)
        # (response [3, C], inverses [J, C, 3]) of the proposed network's illuminant search
        self.register_buffer("response", None if illuminant is None else torch.as_tensor(illuminant[0]).float(),
                             persistent=False)
        self.register_buffer("inverses", None if illuminant is None else torch.as_tensor(illuminant[1]).float(),
                             persistent=False)
        cin = 0
        if variant != "uncoded_only":
            self.coded = CodedFeatures(n_bands, features, raw=False)
            cin += self.coded.channels
        if variant != "coded_only":
            self.feat_uncoded = nn.Sequential(nn.Conv2d(3, 16, 3, padding=1), nn.LeakyReLU(0.1))
            cin += 16
        self.unet = UNet(cin, n_bands, width)
        nn.init.zeros_(self.unet.out.weight)  # start exactly at the baseline: zero residual head
        nn.init.zeros_(self.unet.out.bias)

    def forward(self, coded: torch.Tensor, uncoded: torch.Tensor, psf: torch.Tensor | None = None) -> torch.Tensor:
        parts = []
        if self.variant != "uncoded_only":
            check_input(coded, "coded")
            psf = check_psf(psf, self.n_bands, "the coded PSF of every band")
            parts.append(self.coded(coded, psf))
        if self.variant != "coded_only":
            check_input(uncoded, "uncoded")
            parts.append(self.feat_uncoded(uncoded))
        y = self.unet(torch.cat(parts, dim=1)) + self._baseline(coded, uncoded, psf)
        return y if self.training else y.clamp_min(0.0)

    # [1, J] weights of the candidate lights fixed by the caller (None: estimated from each input): a tiled
    # reconstruction (doefab.lab.reconstruct) estimates a scene's light once, for all its tiles
    light = None

    def _baseline(self, coded, uncoded, psf) -> torch.Tensor:
        if self.variant == "proposed" and self.inverses is not None:
            if self.light is not None:
                w = self.light.expand(uncoded.shape[0], -1)
                return torch.einsum("bj,joc,bchw->bohw", w, self.inverses, uncoded)
            if self.mix:
                w = mix_illuminants(coded, uncoded, psf[0], self.response, self.inverses)
                w = w / w.sum(dim=1, keepdim=True).clamp_min(1e-12)  # a blend of estimates, not a gain
                return torch.einsum("bj,joc,bchw->bohw", w, self.inverses, uncoded)
            idx, _ = search_illuminant(coded, uncoded, psf[0], self.response, self.inverses)
            return torch.einsum("boc,bchw->bohw", self.inverses[idx], uncoded)
        if self.variant == "coded_only":
            return register_bands(coded, self.baseline, dispersion_offsets(psf[0]))
        return torch.einsum("oc,bchw->bohw", self.baseline, uncoded)
