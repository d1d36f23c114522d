"""The building blocks of the reconstruction networks (the paper's sections 4.2–4.5), scaled to train on a CPU.

One network module per application, named by its row of ``doefab.applications`` (``network``):
``hdrnet.HDRNet`` (G_HDR), ``spectralnet.SpectralNet`` (G_HS) and ``depthnet.DepthNet`` (G_depth). Each module
has ``default_arch(variant)``, ``build(variant, arch)`` and ``loss(pred, target)`` (``models`` looks them up).
Each network comes in three variants with the same architecture and budget: ``proposed`` (both captures),
``coded_only`` and ``uncoded_only`` (what a conventional camera sees); the captures a variant sees
(``VIEWS``) are fixed when the network is built. Shared here: ``CodedFeatures`` (DWDN: learned features of the
coded capture Wiener-deconvolved in feature space with the PSF given at call time, so a measured or fabricated
PSF can be swapped in) and a small ``UNet``.

Inputs are [B, 3, H, W] with H and W multiples of 32 (≥ 64).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from doefab.errors import DoefabError
from doefab.reconstruction.wiener import WienerDeconvolution, wiener_deconvolve, wiener_filter

__all__ = ["VARIANTS", "VIEWS", "views_of", "check_input", "check_psf", "UNet", "CodedFeatures"]

VARIANTS = ("proposed", "coded_only", "uncoded_only")
VIEWS = {"proposed": ("coded", "uncoded"), "coded_only": ("coded",), "uncoded_only": ("uncoded",)}  # what each sees


def views_of(variant: str) -> tuple[str, ...]:
    """The captures a network of ``variant`` sees (``VIEWS``); a DoefabError naming the variants for any other."""
    if variant not in VARIANTS:
        raise DoefabError(f"variant must be one of {VARIANTS}, got {variant!r}")
    return VIEWS[variant]


def check_input(x: torch.Tensor, name: str) -> None:
    if x.ndim != 4 or x.shape[1] != 3:
        raise DoefabError(f"{name} must be [B, 3, H, W], got {tuple(x.shape)}")
    h, w = x.shape[-2:]
    if h % 32 or w % 32 or h < 64 or w < 64:
        raise DoefabError(f"{name} is {h}×{w} (H×W): image sides must be multiples of 32 and at least 64: crop, or "
                          f"pad by edge replication (np.pad(x, ((0, 0), (0, ph), (0, pw)), mode=\"edge\")) and crop "
                          f"the result back, or use doefab.lab.reconstruct.reconstruct_tiled, which takes any size of "
                          f"at least 64 px")


def conv_block(cin, cout):
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.LeakyReLU(0.1), nn.Conv2d(cout, cout, 3, padding=1),
                         nn.LeakyReLU(0.1))


class UNet(nn.Module):
    """A small U-Net: ``levels`` poolings, widths ``w·2^i``."""

    def __init__(self, cin: int, cout: int, width: int = 16, levels: int = 3):
        super().__init__()
        self.down = nn.ModuleList([conv_block(cin if i == 0 else width * 2 ** (i - 1), width * 2**i) for i in range(levels)])
        self.mid = conv_block(width * 2 ** (levels - 1), width * 2**levels)
        self.up = nn.ModuleList([nn.ConvTranspose2d(width * 2 ** (i + 1), width * 2**i, 2, 2) for i in range(levels)])
        self.dec = nn.ModuleList([conv_block(width * 2 ** (i + 1), width * 2**i) for i in range(levels)])
        self.out = nn.Conv2d(width, cout, 1)

    def forward(self, x):
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
            x = F.max_pool2d(x, 2)
        x = self.mid(x)
        for i in reversed(range(len(self.up))):
            x = self.dec[i](torch.cat([self.up[i](x), skips[i]], dim=1))
        return self.out(x)


class CodedFeatures(nn.Module):
    """Learned features of the coded capture, Wiener-deconvolved in feature space (DWDN) with the PSF given at
    call time: ``psf`` [B or 1, n_psf, K, K]. ``raw``: the capture's own channels are deconvolved too, each with
    its colour's PSF (HDR); otherwise every feature is deconvolved with every PSF (one per band)."""

    def __init__(self, n_psf: int, features: int, raw: bool):
        super().__init__()
        self.n_psf, self.features, self.raw = n_psf, features, raw
        self.feat_coded = nn.Sequential(nn.Conv2d(3, features, 3, padding=1), nn.LeakyReLU(0.1),
                                        nn.Conv2d(features, features, 3, padding=1))
        self.channels = 3 + 3 * features if raw else n_psf * features
        self.wiener = WienerDeconvolution(self.channels, lam0=1e-2)

    def forward(self, coded: torch.Tensor, psf: torch.Tensor) -> torch.Tensor:
        f = self.feat_coded(coded)
        lam = self.wiener.lam
        # learned feature f with PSF c is channel c·F + f: each feature transformed once, not once per PSF
        out = self._deconvolve("features", f, psf, lam[-psf.shape[1] * self.features:], True)
        if self.raw:  # raw colour channel c with PSF c first
            out = torch.cat([self._deconvolve("raw", coded, psf, lam[:3], False), out], dim=1)
        return out

    def _apply(self, fn, *args, **kwargs):  # moved or cast (``.to``, ``.cpu``, ``.double``): no filter kept
        self.__dict__.pop("_filters", None)
        return super()._apply(fn, *args, **kwargs)

    def _deconvolve(self, slot: str, y: torch.Tensor, psf: torch.Tensor, lam: torch.Tensor,
                    each: bool) -> torch.Tensor:
        """``wiener_deconvolve``; without autograd, the filter of the last PSF and λ is kept per ``slot`` and
        reused while they (compared value for value) and the input's size stay the same: a reconstruction with
        one PSF pays for its filter once, with the same numbers. (Forward-mode AD is not served: it runs under
        ``no_grad`` too.)"""
        if torch.is_grad_enabled():
            return wiener_deconvolve(y, psf, lam, each)
        key = (tuple(y.shape[1:]), y.dtype, y.device, each, tuple(psf.shape), psf.dtype, psf.device, lam.dtype)
        held = self.__dict__.setdefault("_filters", {}).get(slot)
        if held is None or held[0] != key or not torch.equal(held[1], psf) or not torch.equal(held[2], lam):
            held = (key, psf.clone(), lam.clone(), wiener_filter(psf, lam, y.shape[-2:], y.shape[1], each, y.dtype))
            self._filters[slot] = held
        return wiener_deconvolve(y, psf, lam, each, filt=held[3])


def check_psf(psf, n: int, what: str) -> torch.Tensor:
    if psf is None or psf.ndim != 4 or psf.shape[1] != n:
        raise DoefabError(f"psf must be [B, {n}, K, K] ({what}), got {None if psf is None else tuple(psf.shape)}")
    return psf
