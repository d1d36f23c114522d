"""A finished design and its folder format (a contract for masks, holder and tolerance work).

Folder: ``design.json`` (task, camera, wavelengths, depths, metrics, seed, versions, ``n_levels`` L — 16 when a
record predates it — and ``levels_sha256``), ``levels.npy`` (uint8 0..L−1), ``levels.png`` (16-bit, value =
level · 65536 / L so it is visible), ``height.npy``
(float64 metres), ``psf_*.png`` (target beside result) and ``history.csv``. Loading validates shape, dtype,
level range and checksum and refuses a corrupt or mismatched folder with the reason.
"""

from __future__ import annotations

import io
import json
import math
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError
from doefab.validate import distance_or_inf, distance_record
from doefab.fabrication.levels import levels_sha256, levels_to_height
from doefab.fabrication.process import DEFAULT_LEVELS, check_levels
from doefab.io import atomic_write_bytes, atomic_write_json, atomic_write_text, read_json
from doefab.optics.camera import Camera, require_camera

__all__ = ["Design", "levels_sha256", "FORMAT_VERSION", "design_folder_of", "shipped_design_name", "committed_name",
           "designs_inside_hint", "DESIGN_FILES"]

FORMAT_VERSION = 1
# what ``Design.save`` writes into its folder (design.json last); an earlier design's go before a fresh run
DESIGN_FILES = ("design.json", "levels.npy", "height.npy", "levels.png", "psf_target_vs_design.png", "history.csv")


def _versions() -> dict:
    import doefab

    out = {"doefab": doefab.__version__, "python": platform.python_version(), "numpy": np.__version__}
    try:
        import torch

        out["torch"] = torch.__version__
    except ImportError:  # pragma: no cover
        pass
    return out


def design_folder_of(path: str | Path) -> Path:
    """The design folder ``path`` names: itself, a mask set's ``design/``, or, where nothing is at ``path``, the
    committed design it names (``streak``, or ``masks/streak`` and ``masks/streak/design`` as the repository's mask
    sets are called: an installed package has no ``masks/`` folder) unpacked from the package (``committed_dir``).

    Example: ``design_folder_of("masks/streak")`` is ``masks/streak/design`` in the repository, and the unpacked
    committed design elsewhere."""
    d = Path(path)
    if (d / "design" / "design.json").is_file():
        return d / "design"
    named = shipped_design_name(d)
    if named is None:
        return d
    from doefab.design.committed import committed_dir

    return committed_dir(named)


def shipped_design_name(path: str | Path) -> str | None:
    """The committed design ``path`` names where nothing is at it (``streak``, ``masks/streak``,
    ``masks/streak/design``: the repository's mask sets), else None: what ``design_folder_of`` unpacks.

    Example: ``shipped_design_name("masks/half-ring")`` is ``"half-ring"`` where no ``masks/`` folder is."""
    return None if Path(path).exists() else committed_name(path)


def committed_name(path: str | Path) -> str | None:
    """The committed design a relative ``path`` names by its shape alone (``streak``, ``masks/streak``,
    ``masks/streak/design``), whether or not anything is at it; None for any other path.

    Example: ``committed_name("masks/streak/design")`` is ``"streak"``; ``committed_name("out/streak")`` is None."""
    from doefab.design.committed import COMMITTED

    d = Path(path)
    parts = d.parts[:-1] if d.parts[-1:] == ("design",) else d.parts  # masks/streak/design names it too
    named = parts[-1] if len(parts) == 1 or (len(parts) == 2 and parts[0] == "masks") else None
    return named if named in COMMITTED else None


def designs_inside_hint(folder: str | Path) -> str:
    """The end of a "not a design folder" message: ``"; it holds a, b: give one of them"`` naming the design
    folders and mask sets directly inside ``folder`` (the first six), or ``""`` where it holds none or cannot be
    read (no hint rather than a misleading permission error).

    Example: ``designs_inside_hint("masks")`` is ``"; it holds grating, half-ring, streak: give one of them"``."""

    def holds(c: Path) -> bool:
        try:
            return (c / "design.json").is_file() or (c / "design" / "design.json").is_file()
        except OSError:  # a child this user may not enter
            return False

    try:
        inside = sorted(c.name for c in Path(folder).iterdir() if holds(c))
    except OSError:
        return ""
    return f"; it holds {', '.join(inside[:6])}{' …' if len(inside) > 6 else ''}: give one of them" if inside else ""


@dataclass
class Design:
    """A quantized DOE design.

    Attributes:
        task: task name.  task_params: the task's parameters.  camera: the camera it was designed for.
        wavelengths: metres.  depths: metres.  height: (N, N) float64 metres (continuous design).
        levels: (N, N) uint8 0..n_levels−1 (what the masks make).  metrics: task metric, continuous and quantized.
        seed, optimizer, iterations: how it was made.  history: rows (step, wall_time_s, loss, metric).
        psf_quantized / targets: optional (n_depths, n_wavelengths, K, K) arrays for the figures.
        n_levels: L, the levels the fab makes (2, 4, 8, 16 or 32: log2 L binary masks).

    Example:

        >>> import doefab
        >>> from doefab.design.committed import committed_dir
        >>> d = doefab.Design.load(committed_dir("streak"))  # a design folder: design.json + levels.npy
        >>> d.task, d.n_levels, d.levels.shape
        ('streak', 16, (3200, 3200))
    """

    task: str
    task_params: dict
    camera: Camera
    wavelengths: tuple
    depths: tuple
    height: np.ndarray
    levels: np.ndarray
    metrics: dict
    seed: int = 0
    optimizer: str = "adam"
    iterations: int = 0
    history: list = field(default_factory=list)
    psf_quantized: np.ndarray | None = None
    targets: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    n_levels: int = DEFAULT_LEVELS

    def __post_init__(self) -> None:
        require_camera(self.camera, "Design.camera")
        check_levels(self.n_levels, "Design.n_levels")
        top = int(np.asarray(self.levels).max(initial=0))
        if top >= self.n_levels:
            raise DoefabError(f"the level map holds level {top} but the design has n_levels = {self.n_levels} "
                              f"(levels 0..{self.n_levels - 1}): pass the n_levels it was quantized to")

    @property
    def kernel_size(self) -> int:
        """K, the PSF window (sensor pixels) of the design's task: its ``task_params``' kernel_size, else the task's
        default (a design need not store it)."""
        from doefab.tasks import get_task

        return int(get_task(self.task, **self.task_params).kernel_size)

    @property
    def quantized_height(self) -> np.ndarray:
        """(N, N) float64 metres of the L-level design (level · d)."""
        return levels_to_height(self.levels, self.camera, self.n_levels)

    def to_json(self) -> dict:
        """The ``design.json`` record: task, camera (metres), wavelengths and depths (metres), metrics, level
        step (metres), shape, ``levels_sha256`` and the versions that made it."""
        return {
            "format_version": FORMAT_VERSION,
            "task": self.task,
            "task_params": self.task_params,
            "camera": self.camera.to_dict(),
            "wavelengths_m": list(self.wavelengths),
            "depths_m": [distance_record(z) for z in self.depths],
            "metrics": self.metrics,
            "seed": self.seed,
            "optimizer": self.optimizer,
            "iterations": self.iterations,
            "n_levels": self.n_levels,
            "level_step_m": float(levels_to_height(np.array([1], np.uint8), self.camera, self.n_levels)[0]),
            "shape": list(self.levels.shape),
            "row0": "top",
            "levels_sha256": levels_sha256(self.levels),
            "versions": _versions(),
            **({"extra": self.extra} if self.extra else {}),
        }

    def write_level_image(self, folder: str | Path) -> Path:
        """``levels.png`` in ``folder``: the level map as a 16-bit image (level × 65536 / L), to look at."""
        path = Path(folder) / "levels.png"
        _write_png16(path, self.levels.astype(np.uint16) * (65536 // self.n_levels))
        return path

    def save(self, path: str | Path) -> Path:
        """Write the design folder (each file atomically; ``design.json`` last)."""
        out = Path(path)
        out.mkdir(parents=True, exist_ok=True)
        for name, arr in (("levels.npy", self.levels.astype(np.uint8)), ("height.npy", self.height)):
            buf = io.BytesIO()
            np.save(buf, arr)
            atomic_write_bytes(out / name, buf.getvalue())
        self.write_level_image(out)
        if self.history:
            lines = ["step,wall_time_s,loss,metric"] + [",".join(f"{v:.6g}" if isinstance(v, float) else str(v)
                                                                for v in row) for row in self.history]
            atomic_write_text(out / "history.csv", "\n".join(lines) + "\n")
        if self.psf_quantized is not None and self.targets is not None:
            self._figures(out)
        atomic_write_json(out / "design.json", self.to_json())
        return out

    def _figures(self, out: Path) -> None:
        from doefab.plotting import design_psf_figure

        design_psf_figure(out / "psf_target_vs_design.png", self, self.psf_quantized, self.targets, panels_max=6)

    @classmethod
    def load(cls, path: str | Path) -> "Design":
        """Read and validate a design folder."""
        path = Path(path)
        meta_path = path / "design.json"
        if path.is_file():
            raise DoefabError(f"{path} is a file, not a design folder (give the folder holding design.json)")
        if not meta_path.is_file():
            raise DoefabError(f"{path} is not a design folder: design.json is missing")
        try:
            meta = read_json(meta_path)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DoefabError(f"{meta_path} is not valid JSON ({exc})") from None
        meta = _check_meta(meta, meta_path)
        camera = Camera.from_dict(meta["camera"], where=f"{meta_path}: camera")
        n_levels = meta["n_levels"]
        step = float(levels_to_height(np.array([1], np.uint8), camera, n_levels)[0])
        if abs(meta["level_step_m"] - step) > 1e-6 * step:
            raise DoefabError(f"{meta_path}: level_step_m {meta['level_step_m']!r} disagrees with the camera's "
                              f"material, design wavelength and n_levels = {n_levels} ({step:.6g} m = λ / (n − 1) / "
                              f"{n_levels}): the record was edited or made by another process; re-run doefab design")
        n = camera.doe_pixels
        levels = _load_npy(path / "levels.npy")
        if levels.dtype != np.uint8:
            raise DoefabError(f"{path / 'levels.npy'} has dtype {levels.dtype}; expected uint8 levels 0..{n_levels - 1}")
        if levels.shape != (n, n) or tuple(meta["shape"]) != levels.shape:
            raise DoefabError(f"{path / 'levels.npy'} has shape {levels.shape}, design.json says {meta['shape']} and "
                              f"the camera grid is ({n}, {n}): the folder is inconsistent")
        if levels.max(initial=0) >= n_levels:
            raise DoefabError(f"{path / 'levels.npy'} holds level {int(levels.max())}; a {n_levels}-level design "
                              f"(design.json n_levels) has levels 0..{n_levels - 1}")
        if levels_sha256(levels) != meta["levels_sha256"]:
            raise DoefabError(f"{path / 'levels.npy'} does not match levels_sha256 in design.json: the level map "
                              f"was changed or corrupted")
        hp = path / "height.npy"
        height = _load_npy(hp) if hp.is_file() else levels_to_height(levels, camera, n_levels)
        if height.shape != (n, n) or not np.all(np.isfinite(height)):
            raise DoefabError(f"{hp} must be a finite ({n}, {n}) array of heights in metres")
        depths = tuple(meta["depths_m"])
        return cls(task=meta["task"], task_params=meta.get("task_params", {}), camera=camera,
                   wavelengths=tuple(meta["wavelengths_m"]), depths=depths, height=height, levels=levels,
                   metrics=meta["metrics"], seed=meta["seed"], optimizer=meta.get("optimizer", ""),
                   iterations=meta.get("iterations", 0), extra=meta.get("extra", {}), n_levels=n_levels)


def _check_meta(meta, where: Path) -> dict:
    """Every field of design.json that is used, checked for type, finiteness and unit plausibility."""
    from doefab.tasks import TASKS

    if not isinstance(meta, dict):
        raise DoefabError(f"{where}: must hold a JSON object")
    need = ("format_version", "task", "camera", "wavelengths_m", "depths_m", "metrics", "seed", "levels_sha256",
            "level_step_m", "shape")
    missing = [k for k in need if k not in meta]
    if missing:
        raise DoefabError(f"{where} lacks the fields {missing}: not a doefab design.json (format {FORMAT_VERSION})")
    out = dict(meta)

    def bad(key, what):
        raise DoefabError(f"{where}: {key} {what}")

    if meta["format_version"] != FORMAT_VERSION:
        bad("format_version", f"is {meta['format_version']!r}; this doefab reads format {FORMAT_VERSION}")
    if meta["task"] not in TASKS:
        bad("task", f"{meta['task']!r} is not one of {sorted(TASKS)}")
    out["n_levels"] = meta.get("n_levels", DEFAULT_LEVELS)  # records written before L was a choice: 16
    try:
        check_levels(out["n_levels"], "n_levels")
    except DoefabError as exc:
        raise DoefabError(f"{where}: {exc}") from None
    lam = meta["wavelengths_m"]
    if not isinstance(lam, list) or not lam:
        bad("wavelengths_m", "must be a non-empty list of wavelengths in metres")
    for v in lam:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 200e-9 <= v <= 2e-6:
            bad("wavelengths_m", f"holds {v!r}: wavelengths are metres within 200 nm – 2 µm (550 nm is 5.5e-07)")
    zs = meta["depths_m"]
    if not isinstance(zs, list) or not zs:
        bad("depths_m", "must be a non-empty list of depths in metres (or \"inf\")")
    depths = []
    for z in zs:
        d = distance_or_inf(z)
        if d is not None and (d == math.inf or 0 < d <= 1e6):
            depths.append(d)
        else:
            bad("depths_m", f"holds {z!r}: depths are metres > 0 (or \"inf\")")
    out["depths_m"] = depths
    for key in ("seed", "iterations"):
        v = meta.get(key, 0)
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            bad(key, f"must be a non-negative integer, got {v!r}")
    step = meta["level_step_m"]
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not math.isfinite(step) or not 1e-9 < step < 1e-5:
        bad("level_step_m", f"= {step!r} is not a plausible level step in metres (tens of nanometres)")
    shape = meta["shape"]
    if not (isinstance(shape, list) and len(shape) == 2 and all(isinstance(x, int) and x > 0 for x in shape)):
        bad("shape", f"must be [N, N] in pixels, got {shape!r}")
    m = meta["metrics"]
    if not isinstance(m, dict):
        bad("metrics", "must be an object")
    for key in ("continuous", "quantized", "continuous_worst", "quantized_worst"):
        v = m.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1):
            bad(f"metrics.{key}", f"= {v!r} is not a fraction in [0, 1]")
    if not isinstance(meta.get("task_params", {}), dict) or not isinstance(meta.get("extra", {}), dict):
        bad("task_params/extra", "must be objects")
    return out


def _load_npy(path: Path) -> np.ndarray:
    if not path.is_file():
        raise DoefabError(f"{path} is missing")
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DoefabError(f"{path} is not a readable .npy array ({exc})") from None


def _write_png16(path: Path, img: np.ndarray) -> None:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img.astype(np.uint16)).save(buf, format="PNG")
    atomic_write_bytes(path, buf.getvalue())
