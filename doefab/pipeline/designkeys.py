"""The design keys of a scene that depend on the committed design's settings: ``design.knots`` shapes a radial
profile only, and a radial profile forms only a target that is itself rotationally symmetric (the half-ring's
rings). ``resolve`` refuses the first before any folder is made and says the second, so ``doctor`` names both.
"""

from __future__ import annotations

__all__ = ["parameterization", "design_key_problems", "design_key_warnings"]


def parameterization(scene, cfg: dict) -> str:
    """The scene's ``design.parameterization``, else the committed design's (``cfg``: its config), else pixel.

    Example: ``parameterization(scene, {"parameterization": "radial"})`` → ``"radial"`` for a scene without the key.
    """
    return scene.design.get("parameterization", cfg.get("parameterization", "pixel"))


def design_key_problems(scene, cfg: dict) -> list[str]:
    """``design.knots`` on a pixel design (the design stage would stop at it), with the fix."""
    name = parameterization(scene, cfg)
    if scene.design.get("knots", 0) and name != "radial":
        whose = "" if "parameterization" in scene.design else " (the committed design's)"
        return [f"design.knots = {scene.design['knots']}: knots shape a radial profile only, and this scene's design "
                f"is {name}{whose}: delete design.knots, or set design.parameterization = \"radial\""]
    return []


def design_key_warnings(scene, cfg: dict, task) -> list[str]:
    """A radial profile asked of a task whose target it cannot form (``Task.RADIAL_TARGET``)."""
    if parameterization(scene, cfg) != "radial" or task.RADIAL_TARGET:
        return []
    return [f"design.parameterization = \"radial\": a rotationally symmetric relief cannot form the {task.name} "
            f"target (it is not symmetric about the optical axis), so the design cannot reach it; set "
            f"design.parameterization = \"pixel\""]
