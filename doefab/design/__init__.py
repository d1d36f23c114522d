"""Design: optimise a task's height map and quantize it to the L levels a fab makes (16 by default)."""

from doefab.design.design import Design, levels_sha256
from doefab.design.optimize import DesignConfig, optimize

__all__ = ["Design", "DesignConfig", "optimize", "levels_sha256"]
