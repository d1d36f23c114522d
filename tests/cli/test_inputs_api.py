"""Wrong inputs of the public API ``doefab.__all__``: the input sweep's API cases (tables in input_sweep.py), each
a ``doefab.DoefabError`` naming the argument; and the sweep covers every subcommand and every public name."""

from input_sweep import (test_api_argument, test_api_path,  # noqa: F401 - collected here
                         test_every_command_line_case_has_its_subcommands_file, test_the_sweep_covers_the_whole_public_api)


def _valid(name: str):
    """A valid value for a public function's required argument ``name`` (other than its camera)."""
    import numpy as np

    if name in ("height", "levels"):
        return np.zeros((4, 4), dtype=np.int64 if name == "levels" else np.float64)
    if "wavelength" in name:
        return [550e-9] if name.endswith("s") else 550e-9
    if "depth" in name:
        return [5.0] if name.endswith("s") else 5.0
    return {"kernel_size": 31, "gap": 1e-3}.get(name, 1e-3)


def _takes_camera():
    """The public functions and classes (``doefab.__all__``) that take a ``camera``, the level helpers that
    their modules export for the design stage, the mask export's ``LevelMap`` and the tolerance's ``MountedPlan``."""
    import doefab
    from doefab.fabrication import export, levels
    from doefab.tolerance import mounted

    out = {name: getattr(doefab, name) for name in doefab.__all__}
    out.update({f"levels.{n}": getattr(levels, n) for n in ("wrap_height", "quantize_torch")})
    out.update({"export.LevelMap": export.LevelMap, "mounted.MountedPlan": mounted.MountedPlan})
    return {name: f for name, f in out.items() if callable(f) and "camera" in _parameters(f)}


def _parameters(f) -> dict:
    import inspect

    try:
        return dict(inspect.signature(f).parameters)
    except (TypeError, ValueError):  # a builtin without a signature
        return {}


def test_every_function_taking_a_camera_refuses_anything_else_by_name():
    import inspect

    import pytest

    from doefab.errors import DoefabError

    found = _takes_camera()
    assert {"quantize_levels", "levels_to_height", "optimize", "split_aperture_psf", "blank_height", "Design",
            "PSFPlan", "PSFPair", "levels.wrap_height", "levels.quantize_torch", "export.LevelMap",
            "mounted.MountedPlan"} <= set(found)
    for name, f in found.items():
        kw = {p: _valid(p) for p, v in _parameters(f).items()
              if v.default is inspect.Parameter.empty and v.kind is v.POSITIONAL_OR_KEYWORD and p != "camera"}
        for bad, fix in (("hdr", "doefab.Camera.preset('hdr')"), (8.64e-3, "doefab.Camera.preset(name)")):
            with pytest.raises(DoefabError, match="camera must be a doefab.Camera") as exc:
                f(**kw, camera=bad)
            assert fix in str(exc.value), (name, str(exc.value))
