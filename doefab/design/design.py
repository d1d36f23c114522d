"""A finished design and its folder format (a contract for masks, holder and tolerance work).

Folder: ``design.json`` (task, camera, wavelengths, depths, metrics, seed, versions, ``levels_sha256``),
``levels.npy`` (uint8 0..15), ``levels.png`` (16-bit, value = level · 4096 so it is visible), ``height.npy``
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
from doefab.fabrication.levels import N_LEVELS, levels_sha256, levels_to_height
from doefab.io import atomic_write_bytes, atomic_write_json, atomic_write_text
from doefab.optics.camera import Camera

__all__ = ["Design", "levels_sha256", "FORMAT_VERSION"]

FORMAT_VERSION = 1


def _versions() -> dict:
    import doefab

    out = {"doefab": doefab.__version__, "python": platform.python_version(), "numpy": np.__version__}
    try:
        import torch

        out["torch"] = torch.__version__
    except ImportError:  # pragma: no cover
        pass
    return out


def _json_depth(z: float):
    return z if math.isfinite(z) else "inf"


@dataclass
class Design:
    """A quantized DOE design.

    Attributes:
        task: task name.  task_params: the task's parameters.  camera: the camera it was designed for.
        wavelengths: metres.  depths: metres.  height: (N, N) float64 metres (continuous design).
        levels: (N, N) uint8 0..15 (what the masks make).  metrics: task metric, continuous and quantized.
        seed, optimizer, iterations: how it was made.  history: rows (step, wall_time_s, loss, metric).
        psf_quantized / targets: optional (n_depths, n_wavelengths, K, K) arrays for the figures.
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

    @property
    def quantized_height(self) -> np.ndarray:
        """(N, N) float64 metres of the 16-level design (level · d)."""
        return levels_to_height(self.levels, self.camera)

    def to_json(self) -> dict:
        return {
            "format_version": FORMAT_VERSION,
            "task": self.task,
            "task_params": self.task_params,
            "camera": self.camera.to_dict(),
            "wavelengths_m": list(self.wavelengths),
            "depths_m": [_json_depth(z) for z in self.depths],
            "metrics": self.metrics,
            "seed": self.seed,
            "optimizer": self.optimizer,
            "iterations": self.iterations,
            "n_levels": N_LEVELS,
            "level_step_m": float(levels_to_height(np.array([1], np.uint8), self.camera)[0]),
            "shape": list(self.levels.shape),
            "row0": "top",
            "levels_sha256": levels_sha256(self.levels),
            "versions": _versions(),
            **({"extra": self.extra} if self.extra else {}),
        }

    def save(self, path: str | Path) -> Path:
        """Write the design folder (each file atomically; ``design.json`` last)."""
        out = Path(path)
        out.mkdir(parents=True, exist_ok=True)
        for name, arr in (("levels.npy", self.levels.astype(np.uint8)), ("height.npy", self.height)):
            buf = io.BytesIO()
            np.save(buf, arr)
            atomic_write_bytes(out / name, buf.getvalue())
        _write_png16(out / "levels.png", self.levels.astype(np.uint16) * 4096)
        if self.history:
            lines = ["step,wall_time_s,loss,metric"] + [",".join(f"{v:.6g}" if isinstance(v, float) else str(v)
                                                                for v in row) for row in self.history]
            atomic_write_text(out / "history.csv", "\n".join(lines) + "\n")
        if self.psf_quantized is not None and self.targets is not None:
            self._figures(out)
        atomic_write_json(out / "design.json", self.to_json())
        return out

    def _figures(self, out: Path) -> None:
        from doefab.plotting import plot_psf_grid

        psf, tg = self.psf_quantized, self.targets
        nd, nw = psf.shape[:2]
        picks = [(d, w) for d in range(nd) for w in range(nw)]
        if len(picks) > 6:
            idx = np.linspace(0, len(picks) - 1, 6).round().astype(int)
            picks = [picks[i] for i in idx]
        panels = []
        for d, w in picks:
            label = f"{self.wavelengths[w] * 1e9:.0f} nm, z = {self.depths[d]:g} m"
            panels.append((f"target {label}", tg[d, w]))
            panels.append((f"16-level design {label}", psf[d, w]))
        plot_psf_grid(out / "psf_target_vs_design.png", panels, self.camera.sensor_pitch, ncols=2, log=False,
                      suptitle=f"{self.task}: target (left) and quantized design (right), linear scale")

    @classmethod
    def load(cls, path: str | Path) -> "Design":
        """Read and validate a design folder."""
        path = Path(path)
        meta_path = path / "design.json"
        if not meta_path.is_file():
            raise DoefabError(f"{path} is not a design folder: design.json is missing")
        try:
            meta = json.loads(meta_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DoefabError(f"{meta_path} is not valid JSON ({exc})") from None
        for key in ("task", "camera", "wavelengths_m", "depths_m", "metrics", "seed", "levels_sha256"):
            if key not in meta:
                raise DoefabError(f"{meta_path} lacks the field {key!r}")
        camera = Camera.from_dict(meta["camera"])
        n = camera.doe_pixels
        levels = _load_npy(path / "levels.npy")
        if levels.dtype != np.uint8:
            raise DoefabError(f"{path / 'levels.npy'} has dtype {levels.dtype}; expected uint8 levels 0..15")
        if levels.shape != (n, n):
            raise DoefabError(f"{path / 'levels.npy'} has shape {levels.shape} but the camera grid is ({n}, {n})")
        if levels.max(initial=0) >= N_LEVELS:
            raise DoefabError(f"{path / 'levels.npy'} holds level {int(levels.max())}; levels must be 0..15")
        if levels_sha256(levels) != meta["levels_sha256"]:
            raise DoefabError(f"{path / 'levels.npy'} does not match levels_sha256 in design.json: the level map "
                              f"was changed or corrupted")
        hp = path / "height.npy"
        height = _load_npy(hp) if hp.is_file() else levels_to_height(levels, camera)
        if height.shape != (n, n) or not np.all(np.isfinite(height)):
            raise DoefabError(f"{hp} must be a finite ({n}, {n}) array of heights in metres")
        depths = tuple(float("inf") if z == "inf" else float(z) for z in meta["depths_m"])
        return cls(task=meta["task"], task_params=meta.get("task_params", {}), camera=camera,
                   wavelengths=tuple(meta["wavelengths_m"]), depths=depths, height=height, levels=levels,
                   metrics=meta["metrics"], seed=int(meta["seed"]), optimizer=meta.get("optimizer", ""),
                   iterations=int(meta.get("iterations", 0)), extra=meta.get("extra", {}))


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
