"""doefab: split-aperture diffractive optical elements, from wave optics to photomasks and holders.

The public API is re-exported here and imported lazily, so ``import doefab`` stays light (torch loads on
first use of the optics).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_EXPORTS = {
    "Camera": "doefab.optics.camera",
    "PRESETS": "doefab.optics.camera",
    "Material": "doefab.optics.materials",
    "FUSED_SILICA": "doefab.optics.materials",
    "material_by_name": "doefab.optics.materials",
    "blank_height": "doefab.optics.elements",
    "blazed_grating_height": "doefab.optics.elements",
    "split_aperture_psf": "doefab.optics.psf",
    "PSFPlan": "doefab.optics.psf",
    "PSFPair": "doefab.optics.psf",
    "angular_spectrum": "doefab.optics.propagators",
    "gap_transmittance": "doefab.optics.gap",
    "quantize_levels": "doefab.fabrication.levels",
    "quantize_height": "doefab.fabrication.levels",
    "levels_to_height": "doefab.fabrication.levels",
    "level_step": "doefab.fabrication.levels",
    "optimize": "doefab.design.optimize",
    "design_time": "doefab.design.pace",
    "Design": "doefab.design.design",
    "get_task": "doefab.tasks",
    "TASKS": "doefab.tasks",
    "mix_crosstalk": "doefab.imaging.crosstalk",
    "unmix_crosstalk": "doefab.imaging.crosstalk",
    "calibrate_crosstalk": "doefab.imaging.crosstalk",
    "DualPixelCrosstalk": "doefab.imaging.crosstalk",
    "simulate_calibration": "doefab.imaging.crosstalk",
    "sensor_response": "doefab.imaging.sensor",
    "Sensor": "doefab.imaging.sensor",
    "simulate_captures": "doefab.imaging.captures",
    "load_reconstructor": "doefab.reconstruction.loader",
    "depth_encoding_score": "doefab.imaging.depth_score",
    "finetune_end_to_end": "doefab.reconstruction.endtoend",
    "fabricated_height": "doefab.tolerance.fabricate",
    "keep_freed_memory": "doefab._memory",
    "DoefabError": "doefab.errors",
    "SamplingError": "doefab.errors",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'doefab' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
