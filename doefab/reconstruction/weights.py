"""Where a network's weights live and how they are written: the file, its metadata record (design checksum,
architecture, PSF settings, training, validation, the weights' SHA-256) and its validation curve, written
atomically side by side. The shipped weights (``doefab/weights``) are replaced only on explicit request."""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import torch

from doefab.errors import DoefabError
from doefab.io import atomic_write_bytes, atomic_write_json, read_json

__all__ = ["renamed_state", "WEIGHTS_DIR", "weights_paths", "history_path", "is_shipped", "weights_target", "write_weights",
           "WEIGHTS_FORMAT", "foreign_weights_files"]

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
WEIGHTS_FORMAT = "doefab weights 1"


def weights_paths(task: str, variant: str, folder: str | Path | None = None) -> tuple[Path, Path]:
    base = Path(folder) if folder is not None else WEIGHTS_DIR
    return base / f"{task}_{variant}.pt", base / f"{task}_{variant}.json"


def history_path(task: str, variant: str, folder: str | Path | None = None) -> Path:
    """The validation curve kept beside the weights (the report's "training time" plot)."""
    return weights_paths(task, variant, folder)[0].with_name(f"{task}_{variant}_history.csv")


def is_shipped(folder: str | Path | None) -> bool:
    """Whether ``folder`` (None: the default) is the package's shipped weights folder."""
    return folder is None or Path(folder).resolve() == WEIGHTS_DIR.resolve()


def weights_target(weights_dir: str | Path | None, out_dir: str | Path, replace_shipped: bool = False,
                   design=None, task: str | None = None, variant: str | None = None) -> Path:
    """Where training writes its weights: ``weights_dir``, else the run folder ``out_dir``; the shipped folder
    only with ``replace_shipped`` (and only for the committed design). A file of the same name that doefab did
    not write (no weights record of ``task``/``variant`` beside it) is never replaced. Checked before any work."""
    if replace_shipped:
        if design is not None:
            raise DoefabError("--replace-shipped: the shipped weights belong to the committed design; a network "
                              "for --design goes to --out or --weights-dir")
        if weights_dir is not None and not is_shipped(weights_dir):
            raise DoefabError(f"--replace-shipped writes to {WEIGHTS_DIR}; --weights-dir {weights_dir} names "
                              f"another folder: give one of them")
        _check_writable(WEIGHTS_DIR, "--replace-shipped")
        return WEIGHTS_DIR
    target = Path(out_dir if weights_dir is None else weights_dir)
    if is_shipped(target):
        raise DoefabError(f"--weights-dir {target} is the shipped weights folder: pass --replace-shipped to replace "
                          f"the shipped networks (or give another folder)")
    if target.exists() and not target.is_dir():
        raise DoefabError(f"--weights-dir {target} is a file: give a folder")
    _check_writable(target)
    if task is not None and variant is not None:
        foreign = foreign_weights_files(target, task, variant)
        if foreign:
            raise DoefabError(f"{', '.join(map(str, foreign))}: not written by doefab (no doefab weights record "
                              f"beside it), so never replaced: move it away or give another --weights-dir")
    return target


def _check_writable(target: Path, flag: str = "--weights-dir") -> None:
    """Refuse a weights folder that cannot be made or written (a parent that is a file, a read-only place: an
    installed package's own folder too) before any training, not when the weights are written at its end."""
    import os

    here = target.absolute()
    while not here.exists():
        here = here.parent
    if not here.is_dir():
        raise DoefabError(f"{flag} {target}: {here} is a file, so the folder cannot be made: give another")
    if not os.access(here, os.W_OK | os.X_OK):
        fix = "give a folder you can write" if flag == "--weights-dir" else \
            f"drop {flag} and give a --weights-dir you can write"
        raise DoefabError(f"{flag} {target}: {here} is not writable (read-only or another user's): {fix}")


def foreign_weights_files(folder: str | Path, task: str, variant: str) -> list[Path]:
    """The files training ``task``/``variant`` into ``folder`` would replace that doefab did not write: all of
    them unless ``{task}_{variant}.json`` is a doefab weights record of that task and variant."""
    pt, meta = weights_paths(task, variant, folder)
    paths = [p for p in (pt, meta, history_path(task, variant, folder)) if p.exists()]
    if not paths:
        return []
    try:
        rec = read_json(meta)
        ours = (isinstance(rec, dict) and rec.get("format") == WEIGHTS_FORMAT and rec.get("task") == task
                and rec.get("variant") == variant)
    except (OSError, ValueError):
        ours = False
    return [] if ours else paths


def write_weights(folder: str | Path, task: str, variant: str, model: torch.nn.Module, record: dict,
                  history_csv: bytes | None = None) -> dict:
    """Write ``model``'s weights, their metadata (``record`` plus format, task, variant, SHA-256 and file name)
    and the validation curve into ``folder``; returns the metadata with ``weights_path``. The file holds CPU
    tensors whatever device ``model`` is on."""
    state = model.state_dict()
    if any(t.device.type != "cpu" for t in state.values()):
        import copy

        state = copy.deepcopy(model).cpu().state_dict()
    buf = io.BytesIO()
    torch.save(state, buf)
    data = buf.getvalue()
    pt, meta_path = weights_paths(task, variant, folder)
    meta = {"format": WEIGHTS_FORMAT, "task": task, "variant": variant, **record,
            "weights_sha256": hashlib.sha256(data).hexdigest(), "weights_file": pt.name}
    atomic_write_json(meta_path, meta)  # the record first: an interruption leaves a file doefab can replace
    atomic_write_bytes(pt, data)
    if history_csv is not None:
        atomic_write_bytes(history_path(task, variant, folder), history_csv)
    return {**meta, "weights_path": str(pt.resolve())}


def renamed_state(state: dict) -> dict:
    """Weights saved before the coded branch had its own module (``coded.``) load under today's names."""
    old = ("feat_coded.", "wiener.")
    return {("coded." + k if k.startswith(old) else k): v for k, v in state.items()}
