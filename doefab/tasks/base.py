"""What every task declares, and the metric helpers shared by tasks, design, tolerance and reports.

A task is a small object: the camera preset it designs for, the wavelengths / depths / kernel it needs
(nothing more is computed), its target PSFs, its loss, its metric and a starting height map. The
optimiser only talks to this interface, so a fourth task needs no change there.

Every fraction is of all the light through the coded half (0.5 of the aperture's light), not of what
falls inside the simulated window: light thrown outside the window counts as lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from doefab.optics.camera import Camera

__all__ = ["Task", "HALF_LIGHT", "RGB_WAVELENGTHS", "masked_fraction", "softmin", "least_window"]

HALF_LIGHT = 0.5
RGB_WAVELENGTHS = (656e-9, 589e-9, 486e-9)


def masked_fraction(psf: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Fraction of the coded half's light inside ``mask``: sum(psf · mask) / 0.5 over the last two axes."""
    return (psf * mask).sum(dim=(-1, -2)) / HALF_LIGHT


def softmin(x: torch.Tensor, temperature: float = 0.02) -> torch.Tensor:
    """Smooth minimum of a 1-D tensor (→ min as temperature → 0)."""
    return -temperature * torch.logsumexp(-x / temperature, dim=0) + temperature * math.log(x.numel())


def least_window(reach_px: float) -> int:
    """The least odd PSF window (sensor px) whose half, ``kernel_size // 2``, holds a pattern reaching ``reach_px``
    from its centre (to 1e-9 px of rounding, as ``Task.fits_window``).

    Example: ``least_window(62.0)`` → 125; ``least_window(62.3)`` → 127."""
    return 2 * math.ceil(reach_px - 1e-9) + 1


@dataclass
class Task:
    """Base class. Subclasses set ``name``, ``preset`` and implement the methods below.

    Attributes:
        kernel_size: K, sensor pixels of the simulated window.
        loss_kind: which loss drives the design: ``"band"`` (1 − mean in-band fraction: Eq. 26 made
            window-independent), ``"window"`` (band plus 1 − soft-min over bands/depths, which also lifts the
            worst entry) or ``"l1"`` (the paper's L1 to the target scaled to sum 0.5).
        focus_depth: design the PSF for a point at the camera's focus distance (True, default) or at
            the depths the task lists explicitly.
    """

    kernel_size: int = 63
    loss_kind: str = "band"
    wavelengths_m: tuple | None = None  # the bands to design for (metres); None: the task's own
    name: str = field(default="task", init=False)
    preset: str = field(default="default", init=False)
    metric_name: str = field(default="fraction", init=False)
    # run defaults the CLI and optimize() use unless told otherwise (measured choices, see README)
    default_iterations: int = field(default=200, init=False)
    default_lr: float = field(default=0.02, init=False)
    default_batch: int = field(default=0, init=False)

    # numeric parameters: name → (low, high, integer, unit); subclasses add their own
    RANGES = {"kernel_size": (3, 4095, True, "sensor pixels")}

    def __post_init__(self) -> None:
        from doefab.validate import number_in

        for name, (lo, hi, integer, unit) in self.RANGES.items():
            if getattr(self, name) is not None:
                number_in(name, getattr(self, name), lo, hi, integer, unit)
        if self.wavelengths_m is not None:
            from doefab.errors import DoefabError
            from doefab.validate import repeated, wavelengths

            self.wavelengths_m = wavelengths(self.wavelengths_m)
            if twice := repeated(self.wavelengths_m):
                raise DoefabError(f"wavelengths_m holds {', '.join(f'{w * 1e9:g} nm' for w in twice)} more than once: "
                                  f"list each band once")

    def bind(self, camera: Camera) -> None:
        """Fix physical (metre) parameters from the camera the design is for, before any resampling."""

    # what shrinks the pattern instead of widening the window, for ``window_problem``'s message
    PATTERN_HINT = ""
    # the field holding the metric's half-width about its target (sensor px) and its scene key; None: no such width
    METRIC_WIDTH = None  # (field, scene key) in the tasks that have one
    # whether a rotationally symmetric relief (the radial parameterisation) can form the target on the coded half
    RADIAL_TARGET = False

    def pattern_reach_px(self, camera: Camera) -> float:
        """How far from the window's centre the task's target and metric pixels reach on ``camera``, with the
        task's margin (sensor px): they fit a window of ``kernel_size`` while this is at most kernel_size // 2.

        Example: ``StreakTask(arm_px=40).pattern_reach_px(cam)`` → 42 (its arms, the 1 px band, 1 px)."""
        return 0.0

    def fits_window(self, camera: Camera) -> bool:
        """Whether the pattern fits the window: ``pattern_reach_px`` at most kernel_size // 2 (to 1e-9 px of
        rounding: a ring drawn at exactly the edge, 29 · 0.8 / 0.8 = 29.000000000000004, fits).

        Example: ``StreakTask(kernel_size=95, arm_px=45).fits_window(cam)`` → True (47 px of 47)."""
        return self.pattern_reach_px(camera) <= self.kernel_size // 2 + 1e-9

    def window_for_pattern(self, camera: Camera) -> int:
        """The smallest odd window (sensor px) that holds the pattern (``fits_window``): 2·⌈reach⌉ + 1.

        Example: ``StreakTask(arm_px=60).window_for_pattern(cam)`` → 125 (a 62 px reach)."""
        return least_window(self.pattern_reach_px(camera))

    def window_problem(self, camera: Camera) -> str:
        """"" where the task's pattern fits its window on ``camera`` (``pattern_reach_px``), else what to change:
        a pattern past the window's edge would be cut from the targets and metric the design optimises.

        Example: ``StreakTask(arm_px=60).window_problem(cam)`` names kernel_size ≥ 125 (its window: 95 px)."""
        if self.fits_window(camera):
            return ""
        reach, half = self.pattern_reach_px(camera), self.kernel_size // 2
        return (f"{type(self).__name__}: its pattern reaches {reach:.1f} px from the centre (with its margin), beyond "
                f"the {self.kernel_size} px window's {half}: set kernel_size ≥ {self.window_for_pattern(camera)}"
                + (f" or {self.PATTERN_HINT}" if self.PATTERN_HINT else ""))

    # --- what to compute ------------------------------------------------------------------------
    def wavelengths(self, camera: Camera) -> tuple[float, ...]:
        return tuple(self.wavelengths_m) if self.wavelengths_m else RGB_WAVELENGTHS

    def depths(self, camera: Camera) -> tuple[float, ...]:
        return (camera.focus_distance,)

    # --- what to aim for ------------------------------------------------------------------------
    def targets(self, camera: Camera) -> torch.Tensor:
        """(n_depths, n_wavelengths, K, K) target PSFs, each summing to 0.5."""
        raise NotImplementedError

    def band_masks(self, camera: Camera) -> torch.Tensor:
        """(n_depths, n_wavelengths, K, K) 0/1 masks of the pixels that count for the metric."""
        raise NotImplementedError

    def fractions(self, psf: torch.Tensor, camera: Camera, depth_idx=None, wl_idx=None) -> torch.Tensor:
        """(n_depths, n_wavelengths) fraction of the coded light inside the metric band."""
        masks = self.band_masks(camera)
        if depth_idx is not None:
            masks = masks[list(depth_idx)]
        if wl_idx is not None:
            masks = masks[:, list(wl_idx)]
        return masked_fraction(psf, masks.to(psf.device, psf.dtype))

    def loss_from_fractions(self, frac: torch.Tensor) -> torch.Tensor:
        """Band and window losses from in-band fractions of any set of (depth, wavelength) entries."""
        flat = frac.flatten()
        if self.loss_kind == "band":
            return 1.0 - flat.mean()
        if self.loss_kind == "window":
            return (1.0 - flat.mean()) + (1.0 - softmin(flat))
        raise ValueError(f"loss_kind {self.loss_kind!r} is not a fraction loss")

    def loss(self, psf: torch.Tensor, camera: Camera, depth_idx=None, wl_idx=None) -> torch.Tensor:
        """Scalar loss of a (subset of the) PSF stack."""
        if self.loss_kind in ("band", "window"):
            return self.loss_from_fractions(self.fractions(psf, camera, depth_idx, wl_idx))
        if self.loss_kind == "l1":
            tg = self.targets(camera)
            if depth_idx is not None:
                tg = tg[list(depth_idx)]
            if wl_idx is not None:
                tg = tg[:, list(wl_idx)]
            return (psf - tg.to(psf.device, psf.dtype)).abs().sum(dim=(-1, -2)).mean()
        raise ValueError(f"unknown loss_kind {self.loss_kind!r}")

    def metric(self, psf: torch.Tensor, camera: Camera) -> dict:
        """The task metric of a full PSF stack: mean and worst, plus per-entry lists."""
        frac = self.fractions(psf.detach(), camera).double()
        return {"value": float(frac.mean()), "worst": float(frac.min()), "per_entry": frac.tolist()}

    def init_height(self, camera: Camera, rng: np.random.Generator) -> np.ndarray:
        """(N, N) starting height map in metres."""
        raise NotImplementedError

    def params(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_") and not k.startswith("default_")
                and k not in ("name", "preset", "metric_name")}
