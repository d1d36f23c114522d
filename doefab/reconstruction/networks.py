"""The building blocks of the reconstruction networks (the paper's sections 4.2–4.5), scaled to train on a CPU,
and the depth network.

One network per task: ``hdrnet.HDRNet`` (G_HDR), ``spectralnet.SpectralNet`` (G_HS) and ``DepthNet`` here
(G_depth). Each comes in three variants with the same architecture and budget: ``proposed`` (both captures),
``coded_only`` and ``uncoded_only`` (what a conventional camera sees). Shared here: ``CodedFeatures`` (DWDN:
learned features of the coded capture Wiener-deconvolved in feature space with the PSF given at call time, so a
measured or fabricated PSF can be swapped in) and a small ``UNet``.

``DepthNet``: a ResNet-18 trunk encodes each capture — the weights are shared between the two captures, as in
the authors' code: both are images of the same scene through the same lens, and sharing halves the parameters
a CPU has to train — and one decoder turns the concatenated features into metric depth (sigmoid to 0–6 m).
Loss L1 + gradient (Eq. 28, ``depth_loss``). The ``proposed`` variant also gets the cross-blur cost volume of
the two captures (``costvolume.py``: ``p_u(z)∗c − p_c(z)∗u`` vanishes at the true depth plane), encoded by a
small convolution and added to the decoder's input at every scale: the physics of the two halves hands the
network a per-pixel depth cue, and it learns to trust it where the scene has texture and to fill in from context
where it has none. Coded-only and uncoded-only cannot form it (it needs both captures).

Inputs are [B, 3, H, W] with H and W multiples of 32 (≥ 64).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from doefab.errors import DoefabError
from doefab.reconstruction.costvolume import cross_blur_cost, relative_log_cost
from doefab.reconstruction.resnet import ResNet18Trunk
from doefab.reconstruction.wiener import WienerDeconvolution

__all__ = ["DepthNet", "depth_loss", "VARIANTS", "check_input", "check_psf", "UNet", "CodedFeatures"]

VARIANTS = ("proposed", "coded_only", "uncoded_only")


def check_input(x: torch.Tensor, name: str) -> None:
    if x.ndim != 4 or x.shape[1] != 3:
        raise DoefabError(f"{name} must be [B, 3, H, W], got {tuple(x.shape)}")
    h, w = x.shape[-2:]
    if h % 32 or w % 32 or h < 64 or w < 64:
        raise DoefabError(f"{name} is {h}×{w}: image sides must be multiples of 32 and at least 64 (crop or pad)")


def _conv(cin, cout):
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.LeakyReLU(0.1), nn.Conv2d(cout, cout, 3, padding=1),
                         nn.LeakyReLU(0.1))


class UNet(nn.Module):
    """A small U-Net: ``levels`` poolings, widths ``w·2^i``."""

    def __init__(self, cin: int, cout: int, width: int = 16, levels: int = 3):
        super().__init__()
        self.down = nn.ModuleList([_conv(cin if i == 0 else width * 2 ** (i - 1), width * 2**i) for i in range(levels)])
        self.mid = _conv(width * 2 ** (levels - 1), width * 2**levels)
        self.up = nn.ModuleList([nn.ConvTranspose2d(width * 2 ** (i + 1), width * 2**i, 2, 2) for i in range(levels)])
        self.dec = nn.ModuleList([_conv(width * 2 ** (i + 1), width * 2**i) for i in range(levels)])
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
        if self.raw:  # raw colour channel c with PSF c, learned features with every colour's PSF
            stack = torch.cat([coded, f.repeat(1, 3, 1, 1)], dim=1)
            kern = torch.cat([psf, psf.repeat_interleave(self.features, dim=1)], dim=1)
        else:
            stack = f.repeat(1, self.n_psf, 1, 1)
            kern = psf.repeat_interleave(self.features, dim=1)
        return self.wiener(stack, kern)  # one OTF per PSF, broadcast over the batch


def check_psf(psf, n: int, what: str) -> torch.Tensor:
    if psf is None or psf.ndim != 4 or psf.shape[1] != n:
        raise DoefabError(f"psf must be [B, {n}, K, K] ({what}), got {None if psf is None else tuple(psf.shape)}")
    return psf


class DepthNet(nn.Module):
    """G_depth: shared ResNet-18 trunk for both captures, one decoder, metric depth (metres) out."""

    def __init__(self, variant: str = "proposed", width: int = 16, max_depth_m: float = 6.0,
                 cost_volume: bool = False, planes: int = 17, window: int = 9):
        super().__init__()
        if variant not in VARIANTS:
            raise DoefabError(f"variant must be one of {VARIANTS}, got {variant!r}")
        if cost_volume and variant != "proposed":
            raise DoefabError("the cross-blur cost volume needs both captures: use it with the proposed variant only")
        self.variant, self.max_depth = variant, max_depth_m
        self.cost_volume, self.planes, self.window = cost_volume, planes, window
        self.trunk = ResNet18Trunk(3, width)
        n_in = 1 if variant != "proposed" else 2
        ch = [c * n_in for c in self.trunk.channels]
        cf = 16 if cost_volume else 0
        if cost_volume:
            self.cost_enc = nn.Sequential(nn.Conv2d(planes, 32, 3, padding=1), nn.LeakyReLU(0.1),
                                          nn.Conv2d(32, cf, 3, padding=1), nn.LeakyReLU(0.1))
        self.up = nn.ModuleList()
        prev = ch[-1] + cf
        for skip in reversed(ch[:-1]):
            self.up.append(_conv(prev + skip + cf, skip))
            prev = skip
        self.head = nn.Sequential(nn.Conv2d(prev, 16, 3, padding=1), nn.LeakyReLU(0.1), nn.Conv2d(16, 1, 1))

    def forward(self, coded: torch.Tensor, uncoded: torch.Tensor, psf=None) -> torch.Tensor:
        """``psf``: [2, D, 3, K, K] (coded, uncoded) PSFs of the depth planes, needed with the cost volume."""
        inputs = {"proposed": (coded, uncoded), "coded_only": (coded,), "uncoded_only": (uncoded,)}[self.variant]
        for x, name in zip(inputs, ("coded", "uncoded") if self.variant == "proposed" else (self.variant[:-5],)):
            check_input(x, name)
        feats = [self.trunk(x) for x in inputs]
        levels = [torch.cat(fs, dim=1) for fs in zip(*feats)]
        if self.cost_volume:
            if psf is None or psf.ndim != 5 or psf.shape[0] != 2 or psf.shape[1] != self.planes:
                raise DoefabError(f"the depth network needs psf [2, {self.planes}, 3, K, K] (coded and uncoded PSFs "
                                  f"of its depth planes), got {None if psf is None else tuple(psf.shape)}")
            cost = relative_log_cost(cross_blur_cost(coded, uncoded, psf[0], psf[1], self.window))
            cf = self.cost_enc(cost)
            levels = [torch.cat([lv, F.adaptive_avg_pool2d(cf, lv.shape[-2:])], dim=1) for lv in levels]
        y = levels[-1]
        for block, skip in zip(self.up, reversed(levels[:-1])):
            y = F.interpolate(y, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            y = block(torch.cat([y, skip], dim=1))
        y = F.interpolate(self.head(y), size=coded.shape[-2:], mode="bilinear", align_corners=False)
        return self.max_depth * torch.sigmoid(y[:, 0])


def depth_loss(pred: torch.Tensor, target: torch.Tensor, weight: float = 1.0) -> torch.Tensor:
    """Seed Eq. 28: L1 on depth plus L1 on its horizontal and vertical gradients."""
    l1 = (pred - target).abs().mean()
    gx = ((pred[..., :, 1:] - pred[..., :, :-1]) - (target[..., :, 1:] - target[..., :, :-1])).abs().mean()
    gy = ((pred[..., 1:, :] - pred[..., :-1, :]) - (target[..., 1:, :] - target[..., :-1, :])).abs().mean()
    return l1 + weight * (gx + gy)
