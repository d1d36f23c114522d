"""The committed designs, shipped inside the package (so a wheel installed anywhere has them).

Each is ``doefab/designs/<name>.npz``: its ``design.json`` and its level map, compressed. The repository's mask
sets (``masks/<name>/``, the fab deliverables) carry the same design in their ``design/`` folder; a test keeps
the two equal, and ``scripts/rebuild_masks.sh`` re-packs a design it rebuilds (``packing.pack_design``).
``committed_dir(name)`` unpacks a design once into the cache (``$DOEFAB_CACHE``, default ``~/.cache/doefab``) and
returns that folder, a design folder like any other.
"""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np

from doefab.errors import DoefabError

__all__ = ["COMMITTED", "committed_dir", "PACKAGE_DESIGNS"]

COMMITTED = ("streak", "grating", "half-ring")
PACKAGE_DESIGNS = Path(__file__).resolve().parents[1] / "designs"


def committed_dir(name: str) -> Path:
    """The folder of committed design ``name`` (streak, grating, half-ring), unpacked from the package."""
    from doefab.io import atomic_write_bytes, cache_root

    if name not in COMMITTED:
        raise DoefabError(f"no committed design {name!r}: the package ships {', '.join(COMMITTED)}")
    src = PACKAGE_DESIGNS / f"{name}.npz"
    if not src.is_file():
        raise DoefabError(f"the package lacks its committed design {src}: reinstall doefab")
    data = src.read_bytes()
    folder = cache_root() / "designs" / f"{name}-{hashlib.sha256(data).hexdigest()[:16]}"
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        levels, text = z["levels"], z["design_json"].tobytes()
    buf = io.BytesIO()
    np.save(buf, levels)
    # a cached copy that differs from the package's (a damaged disk, an edit) is written afresh, not trusted
    if not (_same(folder / "levels.npy", buf.getvalue()) and _same(folder / "design.json", text)):
        (folder / "design.json").unlink(missing_ok=True)  # absent while the folder is incomplete
        atomic_write_bytes(folder / "levels.npy", buf.getvalue())
        atomic_write_bytes(folder / "design.json", text)  # written last: its presence means complete
    return folder


def _same(path: Path, data: bytes) -> bool:
    try:
        return path.stat().st_size == len(data) and path.read_bytes() == data
    except OSError:
        return False
