"""G_HDR: HDR radiance from the coded (streak) and the uncoded capture.

The network first solves for the radiance by least squares from the captures its variant sees
(``highlights.py``: where the plain capture clips, the streak still holds unclipped, scaled copies of the
highlight; then the bound that a clipped coded pixel received at least full well), takes the log of that
solve as an input and predicts a residual over it in log(1 + radiance). Its other inputs: the coded capture's
raw channels and learned features Wiener-deconvolved with the coded RGB PSF (``CodedFeatures``), and features
of the uncoded capture. It is conditioned on both halves' RGB PSFs, ``psf`` [B or 1, 6, K, K] (coded, then
uncoded); the solve uses the batch's first pair for every image.
"""

from __future__ import annotations

import torch
from torch import nn

from doefab.errors import DoefabError
from doefab.reconstruction.highlights import solve_highlights
from doefab.reconstruction.networks import CodedFeatures, UNet, check_input, check_psf, views_of

__all__ = ["HDRNet", "default_arch", "build", "loss"]


def default_arch(variant: str = "proposed") -> dict:
    """The shipped HDR networks' architecture record: a least-squares solve of the captures the variant sees
    (40 iterations, then 40 more in 8 bounded restarts), 4 coded features, U-Net width 16."""
    return {"features": 4, "width": 16, "highlight_iters": 40, "bound_iters": 40, "bound_rounds": 8}


def build(variant: str, arch: dict) -> nn.Module:
    """The HDR network of ``variant`` from its architecture record (solve settings default to the shipped ones)."""
    return HDRNet(variant, features=int(arch["features"]), width=int(arch["width"]),
                  highlight_iters=int(arch.get("highlight_iters", 40)), bound_iters=int(arch.get("bound_iters", 40)),
                  bound_rounds=int(arch.get("bound_rounds", 8)))


def loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """L1 of log(1 + radiance) over the image (highlights up to 2^8 would otherwise swamp the rest). The paper's
    Eq. 20 adds a highlight term; on validation scenes an added L1 of the highlight pixels relative to their
    radiance did not help (``benchmarks/hdr_loss_pilot.py``: three seeds per loss, highlight PSNR 0.22 dB lower
    on average, paired 95 % interval −1.18 to +0.74 dB), so the log term stands alone."""
    return (torch.log1p(pred) - torch.log1p(target)).abs().mean()


class HDRNet(nn.Module):
    def __init__(self, variant: str = "proposed", features: int = 4, width: int = 16, highlight_iters: int = 40,
                 bound_iters: int = 40, bound_rounds: int = 8):
        super().__init__()
        self.views = views_of(variant)  # the captures this variant sees: its branches and its solve's data
        if highlight_iters < 1:
            raise DoefabError(f"the HDR network starts from a least-squares solve: highlight_iters ≥ 1, got "
                              f"{highlight_iters}")
        self.variant = variant
        self.highlight_iters, self.bound_iters, self.bound_rounds = int(highlight_iters), int(bound_iters), int(
            bound_rounds)
        cin = 3  # log(1 + least-squares radiance)
        self.coded = self.feat_uncoded = None  # a branch for each capture the variant sees
        if "coded" in self.views:
            self.coded = CodedFeatures(3, features, raw=True)
            cin += self.coded.channels + 3
        if "uncoded" in self.views:
            self.feat_uncoded = nn.Sequential(nn.Conv2d(3, 16, 3, padding=1), nn.LeakyReLU(0.1))
            cin += 16
        self.unet = UNet(cin, 3, width)
        nn.init.zeros_(self.unet.out.weight)  # start exactly at the solve: zero residual head
        nn.init.zeros_(self.unet.out.bias)

    def forward(self, coded: torch.Tensor, uncoded: torch.Tensor, psf: torch.Tensor | None = None) -> torch.Tensor:
        psf = check_psf(psf, 6, "the coded then the uncoded RGB PSFs")
        base = self._solve(coded, uncoded, psf[0, :3], psf[0, 3:])
        parts = [base]
        if self.coded is not None:
            check_input(coded, "coded")
            dec = self.coded(coded, psf[:, :3])
            # the deconvolved raw channels estimate half the radiance (the PSF carries half the light) where
            # the capture did not clip; their log puts highlights of up to 2^8 on the output's scale
            parts += [dec, torch.log1p(2.0 * dec[:, :3].clamp_min(0.0))]
        if self.feat_uncoded is not None:
            check_input(uncoded, "uncoded")
            parts.append(self.feat_uncoded(uncoded))
        y = self.unet(torch.cat(parts, dim=1)) + base
        # a linear head in log radiance keeps the L1 gradient alive everywhere; clamped to ≥ 0 outside training
        y = torch.expm1(y.clamp(-5.0, 6.94))
        return y if self.training else y.clamp_min(0.0)

    def _solve(self, coded, uncoded, psf_coded, psf_uncoded) -> torch.Tensor:
        """log(1 + radiance) of the least-squares solve from the captures this variant sees."""
        views = self.views
        seen = {"coded": coded, "uncoded": uncoded}[views[-1]]  # the plain capture when the variant sees it
        check_input(seen, views[-1])
        c = coded if "coded" in views else uncoded  # a capture the variant does not see is never read
        u = uncoded if "uncoded" in views else coded
        return torch.log1p(solve_highlights(c, u, psf_coded, psf_uncoded, self.highlight_iters, views,
                                            bound_iters=self.bound_iters, bound_rounds=self.bound_rounds))
