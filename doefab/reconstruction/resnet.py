"""A ResNet-18 trunk (BasicBlock, layers [2, 2, 2, 2]) written here: torchvision does not import beside the CPU
torch build this project pins. ``width`` scales every stage (64 in the original; smaller trains on a CPU)."""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["BasicBlock", "ResNet18Trunk"]


class BasicBlock(nn.Module):
    """Two 3×3 convolutions with batch norm and an identity (or 1×1 projection) shortcut."""

    def __init__(self, cin: int, cout: int, stride: int = 1):
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(cout)
        self.short = (nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))
                      if stride != 1 or cin != cout else nn.Identity())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = torch.relu(self.bn1(self.conv1(x)))
        return torch.relu(self.bn2(self.conv2(y)) + self.short(x))


class ResNet18Trunk(nn.Module):
    """Stem (7×7 stride-2 convolution, 3×3 max pool) and four stages of two BasicBlocks each.

    ``forward`` returns the feature maps after the stem and after each stage (strides 2, 4, 8, 16, 32), as
    an encoder for a U-Net-like decoder. Channels: ``width · (1, 1, 2, 4, 8)``.
    """

    def __init__(self, in_channels: int = 3, width: int = 64):
        super().__init__()
        w = width
        self.stem = nn.Sequential(nn.Conv2d(in_channels, w, 7, 2, 3, bias=False), nn.BatchNorm2d(w), nn.ReLU())
        self.pool = nn.MaxPool2d(3, 2, 1)
        chans = [w, w, 2 * w, 4 * w, 8 * w]
        self.stages = nn.ModuleList()
        for i in range(4):
            stride = 1 if i == 0 else 2
            self.stages.append(nn.Sequential(BasicBlock(chans[i], chans[i + 1], stride),
                                             BasicBlock(chans[i + 1], chans[i + 1])))
        self.channels = chans

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        feats = [self.stem(x)]
        y = self.pool(feats[0])
        for stage in self.stages:
            y = stage(y)
            feats.append(y)
        return feats
