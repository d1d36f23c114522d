"""G_depth: metric depth from the coded (half-ring) and the uncoded capture.

A ResNet-18 trunk encodes each capture the variant sees — the weights are shared between the two captures, as
in the authors' code: both are images of the same scene through the same lens, and sharing halves the
parameters a CPU has to train — and one decoder turns the concatenated features into metric depth (sigmoid to
0–6 m). Loss L1 + gradient (Eq. 28, ``depth_loss``). The ``proposed`` variant also gets the cross-blur cost
volume of the two captures (``costvolume.py``: ``p_u(z)∗c − p_c(z)∗u`` vanishes at the true depth plane),
encoded by a small convolution and added to the decoder's input at every scale: the physics of the two halves
hands the network a per-pixel depth cue, and it learns to trust it where the scene has texture and to fill in
from context where it has none. Coded-only and uncoded-only cannot form it (it needs both captures).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from doefab.errors import DoefabError
from doefab.reconstruction.costvolume import cross_blur_cost, relative_log_cost
from doefab.reconstruction.networks import check_input, conv_block, views_of
from doefab.reconstruction.resnet import ResNet18Trunk

__all__ = ["DepthNet", "depth_loss", "default_arch", "build", "loss"]


def default_arch(variant: str = "proposed") -> dict:
    """The shipped depth networks' architecture record: width 16, 17 planes; the proposed network adds the two
    captures' cross-blur cost volume (it needs both captures)."""
    return {"width": 16, "cost_volume": variant == "proposed", "planes": 17}


def build(variant: str, arch: dict) -> nn.Module:
    """The depth network of ``variant`` from its architecture record (records without "cost_volume" predate it:
    networks without one; 17 planes: the paper's, 1–5 m in 0.25 m steps)."""
    return DepthNet(variant, width=int(arch["width"]), cost_volume=bool(arch.get("cost_volume", False)),
                    planes=int(arch.get("planes", 17)), max_depth_m=float(arch.get("max_depth_m", 6.0)))


def loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The depth training loss: L1 + gradient (Eq. 28)."""
    return depth_loss(pred, target)


class DepthNet(nn.Module):
    """G_depth: shared ResNet-18 trunk for both captures, one decoder, metric depth (metres) out."""

    def __init__(self, variant: str = "proposed", width: int = 16, max_depth_m: float = 6.0,
                 cost_volume: bool = False, planes: int = 17, window: int = 9):
        super().__init__()
        self.views = views_of(variant)
        if cost_volume and len(self.views) < 2:
            raise DoefabError("the cross-blur cost volume needs both captures: use it with the proposed variant only")
        self.variant, self.max_depth = variant, max_depth_m
        self.cost_volume, self.planes, self.window = cost_volume, planes, window
        self.trunk = ResNet18Trunk(3, width)
        ch = [c * len(self.views) for c in self.trunk.channels]
        cf = 16 if cost_volume else 0
        if cost_volume:
            self.cost_enc = nn.Sequential(nn.Conv2d(planes, 32, 3, padding=1), nn.LeakyReLU(0.1),
                                          nn.Conv2d(32, cf, 3, padding=1), nn.LeakyReLU(0.1))
        self.up = nn.ModuleList()
        prev = ch[-1] + cf
        for skip in reversed(ch[:-1]):
            self.up.append(conv_block(prev + skip + cf, skip))
            prev = skip
        self.head = nn.Sequential(nn.Conv2d(prev, 16, 3, padding=1), nn.LeakyReLU(0.1), nn.Conv2d(16, 1, 1))

    def forward(self, coded: torch.Tensor, uncoded: torch.Tensor, psf=None) -> torch.Tensor:
        """``psf``: [2, D, 3, K, K] (coded, uncoded) PSFs of the depth planes, needed with the cost volume."""
        given = {"coded": coded, "uncoded": uncoded}
        inputs = [given[v] for v in self.views]
        for x, name in zip(inputs, self.views):
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
    """The paper's Eq. 28: L1 on depth plus L1 on its horizontal and vertical gradients."""
    l1 = (pred - target).abs().mean()
    gx = ((pred[..., :, 1:] - pred[..., :, :-1]) - (target[..., :, 1:] - target[..., :, :-1])).abs().mean()
    gy = ((pred[..., 1:, :] - pred[..., :-1, :]) - (target[..., 1:, :] - target[..., :-1, :])).abs().mean()
    return l1 + weight * (gx + gy)
