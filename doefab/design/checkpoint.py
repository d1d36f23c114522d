"""Checkpoints of a design run: written atomically, loaded with ``torch.load(..., weights_only=True)``."""

from __future__ import annotations

import io
import json
from pathlib import Path

import torch

from doefab.errors import DoefabError
from doefab.io import atomic_write_bytes

__all__ = ["save_checkpoint", "load_checkpoint", "read_checkpoint", "clear_checkpoint"]


def save_checkpoint(path: str | Path, state: dict) -> None:
    """Save ``state`` (tensors, numbers, strings, lists, dicts) atomically."""
    buf = io.BytesIO()
    torch.save(state, buf)
    atomic_write_bytes(path, buf.getvalue())


def clear_checkpoint(folder: str | Path, keep: bool = False) -> None:
    """Remove the checkpoint and history writes a kill left half done from ``folder`` and, unless ``keep`` (a resumed
    run), the earlier run's ``checkpoint.pt`` and ``history.csv``: as a fresh run starts there, after everything that
    could refuse it, so that a later resume continues this run, never the earlier one. A ``checkpoint.pt`` or
    ``history.csv`` there that doefab did not write is refused (a DoefabError), never removed or written over."""
    folder = Path(folder)
    names = ("checkpoint.pt", "history.csv")
    foreign = [folder / n for n in names if (folder / n).is_file() and not _written_by_doefab(folder / n)]
    if foreign:
        raise DoefabError(f"{', '.join(map(str, foreign))}: not written by doefab, so never removed or replaced: "
                          f"move it away or give another folder for the run")
    old = [f for n in names for f in folder.glob(f".{n}.*")] + ([] if keep else [folder / n for n in names])
    for f in old:
        if f.is_file():
            f.unlink()


def _written_by_doefab(path: Path) -> bool:
    """Whether a run's ``checkpoint.pt`` (a torch file of a dict with a JSON ``config``) or ``history.csv`` (a
    doefab header: ``step,wall_time_s,...``) is doefab's."""
    if path.suffix == ".csv":
        with open(path, "rb") as f:
            return f.readline().startswith(b"step,wall_time_s,")
    try:
        state = torch.load(path, weights_only=True, map_location="cpu")
    except Exception:  # noqa: BLE001 - a file torch cannot read is not a doefab checkpoint
        return False
    return _doefab_header(state)


def _doefab_header(state) -> bool:
    """A loaded checkpoint is doefab's: a dict whose ``config`` is the JSON of its run's settings."""
    return isinstance(state, dict) and isinstance(state.get("config"), str)


def load_checkpoint(path: str | Path, config: dict, ignore: tuple = ()) -> dict:
    """Load a checkpoint and check its fields and that it belongs to a run with the same ``config``
    (keys in ``ignore`` may differ, e.g. a resumed run may raise ``iterations``)."""
    state, saved = _read(Path(path))
    saved = {k: v for k, v in saved.items() if k not in ignore}
    config = {k: v for k, v in config.items() if k not in ignore}
    if saved != config:
        diff = "; ".join(f"{k}: {a!r} there, {b!r} now" for k, a, b in _differences(saved, config))
        raise DoefabError(f"checkpoint {path} was made with other settings ({diff}): resume with the same settings "
                          f"or start a new --out folder")
    return state


def _differences(saved, asked, prefix: str = "") -> list[tuple]:
    """(key path, saved value, asked value) for each leaf that differs between two settings dicts."""
    if not (isinstance(saved, dict) and isinstance(asked, dict)):
        return [(prefix or "settings", saved, asked)]
    out = []
    for k in sorted(set(saved) | set(asked), key=str):
        a, b = saved.get(k), asked.get(k)
        if a != b:
            name = str(k) if prefix in ("", "config") else f"{prefix}.{k}"
            out += _differences(a, b, name) if isinstance(a, dict) and isinstance(b, dict) else [(name, a, b)]
    return out


def read_checkpoint(path: str | Path) -> dict:
    """A checkpoint whose file and fields are sound, whatever run made it (a resume checks this before any work)."""
    return _read(Path(path))[0]


def _read(path: Path) -> tuple[dict, dict]:
    if not path.is_file():
        raise DoefabError(f"no checkpoint at {path}: nothing to continue: start afresh, without "
                          f"resuming")
    try:
        state = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as exc:  # noqa: BLE001 - any unpickling/zip error means a corrupt file
        raise DoefabError(f"checkpoint {path} is corrupt or not a doefab checkpoint ({exc.__class__.__name__}): "
                          f"move it away, or give another folder, and start afresh, without resuming") from None
    if not _doefab_header(state):
        raise DoefabError(f"checkpoint {path} lacks doefab fields (not a doefab checkpoint): move it away, or give "
                          f"another folder, and start afresh, without resuming")
    try:
        saved = json.loads(state["config"])
        theta = state.get("theta")  # a design's (or an end-to-end run's) parameters, when the run has any
        ok = (isinstance(saved, dict) and (theta is None or (isinstance(theta, torch.Tensor)
                                                             and bool(torch.isfinite(theta).all())))
              and isinstance(state.get("step"), int)
              and state["step"] >= 0 and isinstance(state.get("elapsed"), float) and state["elapsed"] >= 0
              and isinstance(state.get("history"), list) and isinstance(state.get("generator"), torch.Tensor))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise DoefabError(f"checkpoint {path} has missing or invalid fields (config, theta, step, elapsed, history, "
                          f"generator); start afresh, without resuming (a fresh run replaces the "
                          f"checkpoint)")
    return state, saved
