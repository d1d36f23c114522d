"""Dual-pixel crosstalk ratios checked: fractions in [0, 1) whose pair a sensor can have (Eq. 29's determinant
1 − α_l→r − α_r→l > 0); used by the crosstalk model (``imaging.crosstalk``) and its file (``imaging.crosstalkfile``)."""

from __future__ import annotations

import numpy as np

from doefab.errors import DoefabError

__all__ = ["ratio", "check_pair"]


def ratio(name: str, a, like):
    """``a`` checked to be fractions in [0, 1), as the array type of ``like`` (torch tensor or numpy)."""
    vals = np.asarray(a.detach().cpu().numpy() if hasattr(a, "detach") else a, dtype=np.float64)
    if not np.all(np.isfinite(vals)):
        raise DoefabError(f"{name} holds NaN or infinite values: crosstalk ratios are fractions in [0, 1)")
    if np.any(vals < 0) or np.any(vals >= 1):
        raise DoefabError(f"{name} must hold crosstalk fractions in [0, 1), got values in "
                          f"[{vals.min():g}, {vals.max():g}]")
    if hasattr(like, "detach"):
        import torch

        return torch.as_tensor(vals, dtype=like.dtype, device=like.device)
    return vals


def check_pair(alpha_lr, alpha_rl, name: str = "alpha_lr, alpha_rl") -> None:
    """Refuse a ratio pair no dual-pixel sensor has. Each ratio is a fraction in [0, 1) of one view's light that
    lands on the other photodiode (``ratio``), and Eq. 29's determinant ``1 − α_l→r − α_r→l`` must be > 0: at or
    below 0 each photodiode collects as large a share of the other half's light as of its own, so the views do
    not separate (at 0 they are one image; below, the photodiodes are swapped, not crossed)."""
    probe = np.zeros(1)
    a, b = ratio(name.split(", ")[0], alpha_lr, probe), ratio(name.split(", ")[-1], alpha_rl, probe)
    try:
        det = np.atleast_1d(1.0 - a - b)
    except ValueError:
        raise DoefabError(f"{name} must be scalars, per-column profiles or [rows, columns] maps of one shape, got "
                          f"shapes {np.shape(alpha_lr)} and {np.shape(alpha_rl)}") from None
    if det.min() <= 0:
        i = np.unravel_index(int(np.argmin(det)), det.shape)
        where = "" if det.size == 1 else (f" at column {i[-1]}" if det.ndim == 1 or det.shape[0] == 1 else
                                          f" at row {i[0]}, column {i[-1]}")
        raise DoefabError(f"{name} = ({np.broadcast_to(a, det.shape)[i]:g}, {np.broadcast_to(b, det.shape)[i]:g})"
                          f"{where} is no dual-pixel crosstalk: 1 − α_l→r − α_r→l = {det[i]:.3g} ≤ 0, so each "
                          f"photodiode collects as much of the other half's light as of its own and the views do not "
                          f"separate; each ratio is the fraction of a view's light landing on the other photodiode, "
                          f"the two summing below 1 (measured sensors: a few per cent, e.g. (0.05, 0.05))")
