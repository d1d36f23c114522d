"""Writes doefab/measured/hdr_radiance.npz, the HDR radiance maps of the measured-data validation set, from a
checkout of the OpenEXR project's sample images (https://github.com/AcademySoftwareFoundation/openexr-images,
BSD-3-Clause, copyright Industrial Light & Magic and the OpenEXR contributors; its COPYING travels beside the file).

    .venv/bin/python scripts/measured_hdr.py PATH/TO/openexr-images

Each photograph (``PHOTOGRAPHS``, stored with Rec. 709 primaries) is read with OpenEXR, its RGB kept (alpha
dropped, negatives set to 0), resized with anti-aliasing so its short side is ``SHORT_SIDE_PX`` and cut to at most
``LONG_SIDE_PX`` about its centre, and stored as float16 relative radiance; the source files' SHA-256 are stored
with it (``sources``).
"""

from __future__ import annotations

import hashlib
import io
import json
import sys
from pathlib import Path

import numpy as np

from doefab.io import atomic_write_bytes

PHOTOGRAPHS = ("ScanLines/Cannon.exr", "ScanLines/Desk.exr", "ScanLines/MtTamWest.exr", "ScanLines/StillLife.exr",
               "ScanLines/CandleGlass.exr", "Tiles/GoldenGate.exr")
SHORT_SIDE_PX = 400
LONG_SIDE_PX = 560
OUT = Path(__file__).resolve().parents[1] / "doefab" / "measured" / "hdr_radiance.npz"


def read_rgb(path: Path) -> np.ndarray:
    """[H, W, 3] float32 linear RGB of an EXR file with an RGB or RGBA channel group."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        key = "RGB" if "RGB" in ch else "RGBA"
        return np.maximum(np.asarray(ch[key].pixels, np.float32)[..., :3], 0.0)


def shrink(a: np.ndarray) -> np.ndarray:
    from skimage.transform import resize

    h, w = a.shape[:2]
    s = SHORT_SIDE_PX / min(h, w)
    a = resize(a, (round(h * s), round(w * s)), anti_aliasing=True, preserve_range=True, order=1)
    h, w = a.shape[:2]
    if h > LONG_SIDE_PX:
        a = a[(h - LONG_SIDE_PX) // 2:(h - LONG_SIDE_PX) // 2 + LONG_SIDE_PX]
    if w > LONG_SIDE_PX:
        a = a[:, (w - LONG_SIDE_PX) // 2:(w - LONG_SIDE_PX) // 2 + LONG_SIDE_PX]
    return np.ascontiguousarray(a, np.float16)


def main(root: str) -> None:
    root = Path(root)
    arrays, sources = {}, {}
    for rel in PHOTOGRAPHS:
        path = root / rel
        name = Path(rel).stem
        arrays[name] = shrink(read_rgb(path))
        sources[name] = {"file": rel, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
        print(name, arrays[name].shape, f"max {float(arrays[name].max()):.4g}")
    buf = io.BytesIO()
    np.savez_compressed(buf, sources=np.array(json.dumps(sources)), **arrays)
    atomic_write_bytes(OUT, buf.getvalue())
    print(f"wrote {OUT} ({OUT.stat().st_size / 2**20:.1f} MiB)")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
