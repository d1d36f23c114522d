"""The three conditional reconstruction networks (seed sections 4.2–4.5), scaled to train on a CPU.

- ``DeconvNet`` (G_HDR, G_HS): DWDN-like. Features of the coded capture are Wiener-deconvolved in feature space
  with the task's PSF(s) — one PSF for HDR (the coded RGB PSF, per colour channel of the raw capture and
  their mean for the learned features), one per band for hyperspectral — concatenated with features of the
  uncoded capture, and decoded by a small U-Net. The PSF is an input: a measured or fabricated PSF can be
  swapped in at test time. Variants: ``proposed`` (both captures), ``coded_only``, ``uncoded_only`` (no
  deconvolution branch: it sees what a conventional camera sees). The hyperspectral networks predict a
  residual over a linear spectral estimate from one capture; for the proposed one that estimate is the
  smooth inverse under the illuminant the grating's dispersion points to (``illuminant.py``), for the
  ablations one fixed smooth inverse of the sensor response. The HDR networks built with ``highlight_iters``
  (the shipped ones) first solve for the radiance by least squares from the captures their variant sees
  (``highlights.py``: the streak's unclipped copies of what the plain capture clips, then the bound that a
  clipped coded pixel received at least full well), take its log as an
  input and predict a residual over it in log radiance; they are conditioned on both halves' RGB PSFs,
  ``psf`` [B or 1, 6, K, K] (coded, then uncoded).
- ``DepthNet`` (G_depth): a ResNet-18 trunk encodes each capture — the weights are shared between the two
  captures, as in the authors' code: both are images of the same scene through the same lens, and sharing
  halves the parameters a CPU has to train — and one decoder turns the concatenated features into metric
  depth (sigmoid to 0–6 m). Loss L1 + gradient (Eq. 28, ``depth_loss``). The ``proposed`` variant also gets
  the cross-blur cost volume of the two captures (``costvolume.py``: ``p_u(z)∗c − p_c(z)∗u`` vanishes at the
  true depth plane), encoded by a small convolution and added to the decoder's input at every scale: the
  physics of the two halves hands the network a per-pixel depth cue, and it learns to trust it where the
  scene has texture and to fill in from context where it has none. Coded-only and uncoded-only cannot form it
  (it needs both captures), so they see exactly one capture as before.

Inputs are [B, 3, H, W] with H and W multiples of 32 (≥ 64).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from doefab.errors import DoefabError
from doefab.reconstruction.costvolume import cross_blur_cost, relative_log_cost
from doefab.reconstruction.highlights import solve_highlights
from doefab.reconstruction.illuminant import search_illuminant
from doefab.reconstruction.resnet import ResNet18Trunk
from doefab.reconstruction.wiener import WienerDeconvolution

__all__ = ["DeconvNet", "DepthNet", "depth_loss", "VARIANTS", "check_input"]

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


class DeconvNet(nn.Module):
    """G_HDR / G_HS. ``out_channels``: 3 (HDR radiance) or the number of bands; ``n_psf``: PSFs given (3 RGB for
    HDR, one per band for hyperspectral)."""

    def __init__(self, out_channels: int, n_psf: int, variant: str = "proposed", features: int = 4, width: int = 16,
                 log_output: bool = False, baseline=None, illuminant=None, highlight_iters: int = 0,
                 bound_iters: int = 0, bound_rounds: int = 8):
        super().__init__()
        if highlight_iters and not (log_output and n_psf == 3):
            raise DoefabError("highlight_iters is for HDR networks (3 RGB PSFs, log-radiance output)")
        self.highlight_iters = int(highlight_iters)
        self.bound_iters, self.bound_rounds = int(bound_iters), int(bound_rounds)  # the solve's bounded stage
        # optional (response [3, C], inverses [J, C, 3]): the proposed hyperspectral network replaces the fixed
        # baseline by the smooth inverse of the illuminant whose predicted coded capture matches the measured
        # one best (``illuminant.py``) — the dispersion tells illuminants apart that RGB cannot
        self.register_buffer("response", None if illuminant is None else torch.as_tensor(illuminant[0]).float(),
                             persistent=False)
        self.register_buffer("inverses", None if illuminant is None else torch.as_tensor(illuminant[1]).float(),
                             persistent=False)
        # optional linear baseline [out_channels, 3]: the network predicts a residual over baseline @ capture
        # (hyperspectral: a smooth least-squares inverse of the sensor response), so even a briefly trained
        # network starts from a physically sensible spectrum
        self.register_buffer("baseline", None if baseline is None else torch.as_tensor(baseline, dtype=torch.float32),
                             persistent=False)
        if variant not in VARIANTS:
            raise DoefabError(f"variant must be one of {VARIANTS}, got {variant!r}")
        self.variant, self.n_psf, self.log_output = variant, n_psf, log_output
        self.features = features
        cin = 0
        if variant != "uncoded_only":
            self.feat_coded = nn.Sequential(nn.Conv2d(3, features, 3, padding=1), nn.LeakyReLU(0.1),
                                            nn.Conv2d(features, features, 3, padding=1))
            n_dec = 3 + 3 * features if n_psf == 3 else n_psf * features
            self.wiener = WienerDeconvolution(n_dec, lam0=1e-2)
            cin += n_dec + (3 if log_output else 0)
        if variant != "coded_only":
            self.feat_uncoded = nn.Sequential(nn.Conv2d(3, 16, 3, padding=1), nn.LeakyReLU(0.1))
            cin += 16
        if self.highlight_iters:
            cin += 3  # log(1 + least-squares radiance)
        self.unet = UNet(cin, out_channels, width)
        if baseline is not None or self.highlight_iters:  # start exactly at the baseline: zero residual head
            nn.init.zeros_(self.unet.out.weight)
            nn.init.zeros_(self.unet.out.bias)

    def forward(self, coded: torch.Tensor, uncoded: torch.Tensor, psf: torch.Tensor | None = None) -> torch.Tensor:
        """``psf``: [B or 1, n_psf, K, K] coded PSFs (needed unless the variant is uncoded_only); HDR also takes
        [B or 1, 6, K, K], the coded then the uncoded RGB PSFs, which networks with ``highlight_iters`` need
        (their least-squares solve uses the batch's first PSF pair for every image)."""
        parts = []
        psf_uncoded = None
        if self.n_psf == 3 and psf is not None and psf.ndim == 4 and psf.shape[1] == 6:
            psf, psf_uncoded = psf[:, :3], psf[:, 3:]
        if self.highlight_iters:
            if psf_uncoded is None:
                raise DoefabError(f"psf must be [B, 6, K, K] (coded then uncoded RGB PSFs) for an HDR network with "
                                  f"a highlight solve, got {None if psf is None else tuple(psf.shape)}")
            base = self._solve(coded, uncoded, psf[0], psf_uncoded[0])
            parts.append(base)
        if self.variant != "uncoded_only":
            check_input(coded, "coded")
            if psf is None or psf.ndim != 4 or psf.shape[1] != self.n_psf:
                raise DoefabError(f"psf must be [B, {self.n_psf}, K, K], got {None if psf is None else tuple(psf.shape)}")
            f = self.feat_coded(coded)
            if self.n_psf == 3:  # HDR: raw colour channel c with PSF c, learned features with every colour's PSF
                stack = torch.cat([coded, f.repeat(1, 3, 1, 1)], dim=1)
                kern = torch.cat([psf, psf.repeat_interleave(self.features, dim=1)], dim=1)
            else:  # hyperspectral: the features deconvolved with each band's PSF
                stack = f.repeat(1, self.n_psf, 1, 1)
                kern = psf.repeat_interleave(self.features, dim=1)
            dec = self.wiener(stack, kern)  # one OTF per PSF, broadcast over the batch
            parts.append(dec)
            if self.log_output and self.n_psf == 3:
                # HDR: the deconvolved raw colour channels estimate half the radiance (the PSF carries half the
                # light) where the capture did not clip; handing their log to the network puts highlights of
                # up to 2^8 on the scale of its log-radiance output
                parts.append(torch.log1p(2.0 * dec[:, :3].clamp_min(0.0)))
        if self.variant != "coded_only":
            check_input(uncoded, "uncoded")
            parts.append(self.feat_uncoded(uncoded))
        y = self.unet(torch.cat(parts, dim=1))
        if self.inverses is not None and self.variant == "proposed":
            idx, _ = search_illuminant(coded, uncoded, psf[0], self.response, self.inverses)
            y = y + torch.einsum("boc,bchw->bohw", self.inverses[idx], uncoded)
        elif self.baseline is not None:
            src = coded if self.variant == "coded_only" else uncoded
            y = y + torch.einsum("oc,bchw->bohw", self.baseline, src)
        elif self.highlight_iters:
            y = y + base
        # A linear output keeps the L1 gradient alive everywhere (a softplus head died on dark pixels); the
        # result is clamped to ≥ 0 outside training. HDR: the network predicts log(1 + radiance).
        if self.log_output:
            y = torch.expm1(y.clamp(-5.0, 6.94))
        return y if self.training else y.clamp_min(0.0)

    def _solve(self, coded, uncoded, psf_coded, psf_uncoded) -> torch.Tensor:
        """log(1 + radiance) of the least-squares solve from the captures this variant sees."""
        views = {"proposed": ("coded", "uncoded"), "coded_only": ("coded",), "uncoded_only": ("uncoded",)}[self.variant]
        seen = coded if self.variant == "coded_only" else uncoded
        check_input(seen, views[-1])
        c = coded if "coded" in views else uncoded  # a capture the variant does not see is never read
        u = uncoded if "uncoded" in views else coded
        return torch.log1p(solve_highlights(c, u, psf_coded, psf_uncoded, self.highlight_iters, views,
                                            bound_iters=self.bound_iters, bound_rounds=self.bound_rounds))


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
