"""A vectorised GDSII stream writer for many rectangles and a few polygons.

gdstk builds one Python object per shape (about 2 µs each); a 3200² 16-level DOE has ~10⁶ rectangles per
layer set, so the rectangles are packed here as GDSII records with numpy in one pass (BOUNDARY, LAYER,
DATATYPE, XY, ENDEL; GDSII Stream Format release 6). The file is then read back with gdstk (and KLayout
where installed) and compared pixel by pixel with the design, so this writer never goes unchecked.
Coordinates are integer database units (1 nm by default).
"""

from __future__ import annotations

import datetime as _dt
import struct

import numpy as np

__all__ = ["gds_real8", "GDSWriter"]


def gds_real8(value: float) -> bytes:
    """8-byte GDSII real (excess-64, base-16 mantissa)."""
    if value == 0:
        return b"\x00" * 8
    sign = 0x80 if value < 0 else 0
    v = abs(value)
    exp = 64
    while v >= 1:
        v /= 16.0
        exp += 1
    while v < 1 / 16:
        v *= 16.0
        exp -= 1
    mant = int(round(v * (1 << 56)))
    if mant >= 1 << 56:  # rounding carried into a new hex digit
        mant >>= 4
        exp += 1
    return bytes([sign | exp]) + mant.to_bytes(7, "big")


def _record(rtype: int, dtype: int, payload: bytes = b"") -> bytes:
    return struct.pack(">HBB", 4 + len(payload), rtype, dtype) + payload


def _ascii(text: str) -> bytes:
    b = text.encode("ascii")
    return b + (b"\x00" if len(b) % 2 else b"")


def _rect_records(rects: np.ndarray, layer: int, datatype: int) -> bytes:
    """GDSII records for (R, 4) integer rectangles (x0, y0, x1, y1) in database units, vectorised."""
    r = np.asarray(rects, np.int64)
    if r.size == 0:
        return b""
    dt = np.dtype([("bnd", ">u2", 2), ("lay", ">u2", 3), ("dty", ">u2", 3), ("xyh", ">u2", 2),
                   ("xy", ">i4", 10), ("end", ">u2", 2)])
    out = np.zeros(len(r), dt)
    out["bnd"] = (4, 0x0800)
    out["lay"] = (6, 0x0D02, layer)
    out["dty"] = (6, 0x0E02, datatype)
    out["xyh"] = (44, 0x1003)
    x0, y0, x1, y1 = r[:, 0], r[:, 1], r[:, 2], r[:, 3]
    out["xy"] = np.stack([x0, y0, x1, y0, x1, y1, x0, y1, x0, y0], axis=1)
    out["end"] = (4, 0x1100)
    return out.tobytes()


class GDSWriter:
    """Collects shapes for one top cell and returns the GDSII stream.

    Args:
        cell_name: name of the single top cell.  db_unit_m: database unit in metres (1e-9).
        user_unit_m: user unit in metres (1e-6).
    """

    def __init__(self, cell_name: str = "DOE", lib_name: str = "DOEFAB", db_unit_m: float = 1e-9,
                 user_unit_m: float = 1e-6):
        self.cell_name, self.lib_name = cell_name, lib_name
        self.db_unit_m, self.user_unit_m = db_unit_m, user_unit_m
        self._chunks: list[bytes] = []

    def add_rectangles(self, rects: np.ndarray, layer: int, datatype: int = 0) -> None:
        """(R, 4) integer (x0, y0, x1, y1) rectangles in database units."""
        self._chunks.append(_rect_records(rects, layer, datatype))

    def add_polygon(self, points: np.ndarray, layer: int, datatype: int = 0) -> None:
        """One polygon, (P, 2) integer vertices in database units (not closed; P ≤ 8190)."""
        pts = np.asarray(points, np.int64)
        if len(pts) > 8190:
            raise ValueError(f"GDSII polygons hold at most 8190 vertices, got {len(pts)}")
        closed = np.vstack([pts, pts[:1]]).astype(">i4")
        body = (_record(0x08, 0x00) + _record(0x0D, 0x02, struct.pack(">h", layer))
                + _record(0x0E, 0x02, struct.pack(">h", datatype)) + _record(0x10, 0x03, closed.tobytes())
                + _record(0x11, 0x00))
        self._chunks.append(body)

    def _head(self, timestamp: _dt.datetime | None = None) -> bytes:
        t = timestamp or _dt.datetime(2000, 1, 1)
        date = struct.pack(">12h", t.year, t.month, t.day, t.hour, t.minute, t.second,
                           t.year, t.month, t.day, t.hour, t.minute, t.second)
        return (_record(0x00, 0x02, struct.pack(">h", 600)) + _record(0x01, 0x02, date)
                + _record(0x02, 0x06, _ascii(self.lib_name))
                + _record(0x03, 0x05, gds_real8(self.db_unit_m / self.user_unit_m) + gds_real8(self.db_unit_m))
                + _record(0x05, 0x02, date) + _record(0x06, 0x06, _ascii(self.cell_name)))

    _TAIL = _record(0x07, 0x00) + _record(0x04, 0x00)

    def tobytes(self, timestamp: _dt.datetime | None = None) -> bytes:
        return self._head(timestamp) + b"".join(self._chunks) + self._TAIL

    def write(self, path, timestamp: _dt.datetime | None = None) -> int:
        """Stream the library to ``path`` chunk by chunk (no full copy in memory); returns the byte count."""
        n = 0
        with open(path, "wb") as fh:
            for part in (self._head(timestamp), *self._chunks, self._TAIL):
                fh.write(part)
                n += len(part)
        return n
