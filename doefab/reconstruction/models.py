"""Build a task's network from a small JSON-able architecture record (so weights rebuild without pickles)."""

from __future__ import annotations

import torch

from doefab.applications import application
from doefab.reconstruction.networks import views_of
from doefab.reconstruction.specs import get_spec

__all__ = ["default_arch", "build_model", "loss_fn", "network_module"]


def network_module(task: str):
    """The module of ``task``'s network (its application's ``network`` row): it has ``default_arch(variant)``,
    ``build(variant, arch)`` and ``loss(pred, target)``."""
    import importlib

    return importlib.import_module(application(get_spec(task).name).network)


def default_arch(task: str, variant: str = "proposed") -> dict:
    """The architecture record of the shipped ``task`` network of ``variant`` (each network module's
    ``default_arch``: the depth network's width and planes, and for the proposed one the cross-blur cost volume;
    the HDR networks' solve; the hyperspectral networks' illuminant search and mix for the proposed one)."""
    views_of(variant)
    return network_module(task).default_arch(variant)


def build_model(task: str, variant: str, arch: dict | None = None) -> torch.nn.Module:
    """``task``'s network of ``variant`` from its architecture record (default: ``default_arch``)."""
    views_of(variant)
    return network_module(task).build(variant, arch or default_arch(task, variant))


def loss_fn(task: str, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``task``'s training loss (its network module's ``loss``): HDR L1 of log(1 + radiance), hyperspectral L1,
    depth L1 + gradient (Eq. 28)."""
    return network_module(task).loss(pred, target)
