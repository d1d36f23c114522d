"""Packing a design folder as one of the package's committed designs (``doefab/designs/<name>.npz``, which
``committed.committed_dir`` unpacks): ``scripts/rebuild_masks.sh`` re-packs each design it rebuilds.

Example: ``pack_design("masks/grating/design", "grating")`` rewrites ``doefab/designs/grating.npz``.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from doefab.design.committed import PACKAGE_DESIGNS

__all__ = ["pack_design"]


def pack_design(folder: str | Path, name: str, target: str | Path | None = None) -> Path:
    """Write design folder ``folder`` (design.json + levels.npy) as the packaged design ``name``."""
    from doefab.design.design import Design
    from doefab.io import atomic_write_bytes

    folder = Path(folder)
    Design.load(folder)  # only a sound design is shipped
    text = (folder / "design.json").read_bytes()
    levels = np.load(folder / "levels.npy", allow_pickle=False)
    buf = io.BytesIO()
    np.savez_compressed(buf, design_json=np.frombuffer(text, np.uint8), levels=levels)
    out = Path(target) if target is not None else PACKAGE_DESIGNS / f"{name}.npz"
    return atomic_write_bytes(out, buf.getvalue())
