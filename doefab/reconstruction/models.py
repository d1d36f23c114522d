"""Build a task's network from a small JSON-able architecture record (so weights rebuild without pickles)."""

from __future__ import annotations

import torch

from doefab.applications import has
from doefab.errors import DoefabError
from doefab.reconstruction.networks import VARIANTS, DepthNet, depth_loss
from doefab.reconstruction.specs import get_spec

__all__ = ["default_arch", "build_model", "loss_fn", "arch_response", "spectral_baseline"]


def default_arch(task: str, variant: str = "proposed") -> dict:
    """Sizes that train in minutes on a 2-core CPU (the authors' networks take seconds per step here). The
    proposed depth network adds the two captures' cross-blur cost volume (it needs both captures); the HDR
    networks start from a least-squares solve of the captures their variant sees (40 iterations, then 40 more
    in 8 bounded restarts)."""
    if has(get_spec(task).name, "depth"):
        return {"width": 16, "cost_volume": variant == "proposed", "planes": 17}
    if has(task, "spectral"):
        return {"features": 2, "width": 16, "illuminant_search": variant == "proposed",
                "illuminant_mix": variant == "proposed"}
    return {"hdr": {"features": 4, "width": 16, "highlight_iters": 40, "bound_iters": 40, "bound_rounds": 8}}[task]


def build_model(task: str, variant: str, arch: dict | None = None) -> torch.nn.Module:
    spec = get_spec(task)
    if variant not in VARIANTS:
        raise DoefabError(f"variant must be one of {VARIANTS}, got {variant!r}")
    arch = arch or default_arch(task, variant)
    if has(task, "depth"):  # records without "cost_volume" predate it (networks without one)
        return DepthNet(variant, width=int(arch["width"]), cost_volume=bool(arch.get("cost_volume", False)),
                        planes=int(arch.get("planes", 17)),  # 17: the paper's planes, 1–5 m in 0.25 m steps
                        max_depth_m=float(arch.get("max_depth_m", 6.0)))
    if has(task, "highlights"):
        from doefab.reconstruction.hdrnet import HDRNet

        return HDRNet(variant, features=int(arch["features"]), width=int(arch["width"]),
                      highlight_iters=int(arch.get("highlight_iters", 40)), bound_iters=int(arch.get("bound_iters", 40)),
                      bound_rounds=int(arch.get("bound_rounds", 8)))
    from doefab.reconstruction.spectralnet import SpectralNet

    from doefab.reconstruction.data import HS_WAVELENGTHS_M

    bands = tuple(arch.get("wavelengths_m") or HS_WAVELENGTHS_M)  # the design's bands (31 at 400–700 nm)
    t = arch_response(arch, bands)
    return SpectralNet(len(bands), variant, features=int(arch["features"]), width=int(arch["width"]),
                       baseline=spectral_baseline(bands, response=t),
                       illuminant=_illuminant_search(bands, t) if arch.get("illuminant_search") else None,
                       mix=bool(arch.get("illuminant_mix", False)))  # older records: the single best member


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


def loss_fn(task: str, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """HDR: L1 of log(1 + radiance) over the image (highlights up to 2^8 would otherwise swamp the rest). The
    paper's Eq. 20 adds a highlight term; on validation scenes an added L1 of the highlight pixels relative to
    their radiance did not help (``benchmarks/hdr_loss_pilot.py``: three seeds per loss, highlight PSNR 0.22 dB
    lower on average, paired 95 % interval −1.18 to +0.74 dB), so the log term stands alone. Hyperspectral: L1;
    depth: L1 + gradient (Eq. 28)."""
    if has(task, "highlights"):
        return (torch.log1p(pred) - torch.log1p(target)).abs().mean()
    if has(task, "depth"):
        return depth_loss(pred, target)
    return (pred - target).abs().mean()
