"""A scene resolved into the system it describes (``ResolvedScene``): what ``pipeline.system.resolve`` returns and
every stage, ``doctor`` and the report take. It is built once, after every physics check has passed: the camera
(SI units), the task bound to it (bands, planes, geometry), the design settings and whether they equal the
committed design's, the sensor, the die and the warnings.

"The same scene" has one definition: two scene files that resolve to the same design settings are the same
design, whatever they spelled out or left to a default — the reuse check compares ``settings`` with
``committed_settings``, and the design stage's cache key is ``design_key`` (the settings, and the committed
design's level map where it is reused).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ResolvedScene"]


@dataclass(frozen=True)
class ResolvedScene:
    """settings: the design settings the scene asks for (JSON-able: design task, camera, bands in m, planes in m,
    kernel px, task parameters, optimiser, iterations, sampling, seed, parameterization, knots, n_levels).
    camera: the scene's ``Camera``.  task: its design task bound to the camera.  committed_dir, committed,
    committed_settings: the committed design of the task (its folder, its ``Design``, its settings).  reuse:
    settings equal the committed ones; differ: the keys that do not.  custom_camera: the camera differs from its
    preset.  split: the aperture split ("vertical" or "horizontal").  stop: where the aperture stop lies
    (``tolerance.mounted.stop_case``).  sensor: the scene's ``Sensor``.  die_m: the die's side (m).
    quick_sampling: the coarser grid factor of ``--quick``.  warnings: what works but deserves the user's eye.
    stage_warnings: those of them about the run's stages rather than the optical system (a reconstruction stage
    that will be skipped): ``doefab psf --scene`` leaves them out.

    Example::

        >>> from doefab.pipeline.scene import load_scene
        >>> from doefab.pipeline.system import resolve
        >>> res = resolve(load_scene("scenes/hdr.toml"))  # doctest: +SKIP
        >>> res.reuse, res.settings["design_task"]  # doctest: +SKIP
        (True, 'streak')
    """

    settings: dict
    camera: object
    task: object
    committed_dir: Path
    committed: object
    committed_settings: dict
    reuse: bool
    differ: tuple
    custom_camera: bool
    split: str
    stop: str
    sensor: object
    die_m: float
    quick_sampling: int | None
    warnings: tuple = field(default_factory=tuple)
    stage_warnings: tuple = field(default_factory=tuple)

    def design_key(self) -> dict:
        """What the design stage's result depends on: the settings, and for a reused design the committed level
        map's SHA-256 (another doefab version may ship another committed design)."""
        from doefab.fabrication.levels import levels_sha256

        key = {"settings": self.settings}
        if self.reuse:
            key["committed_levels_sha256"] = levels_sha256(self.committed.levels)
        return key
