"""A mask set's layout files read back with gdstk: integer vertices (database units, 1 nm) per (layer, datatype).

A GDSII file is read a few layers at a time (gdstk's layer filter), so checking a large set holds one etch
layer's polygons at a time; gdstk reads OASIS whole, so an OASIS file is read once and its layers are taken
from that reading a few at a time. Either file must hold one top cell (references and repetitions are
flattened into it) and a 1 nm database unit; anything else is a CheckFailed naming the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from doefab.errors import CheckFailed
from doefab.fabrication.layout_check import DBU_NM

__all__ = ["LayerPolygons", "LayoutFile"]


class LayerPolygons:
    """All polygons of one (layer, datatype): concatenated int64 vertices (database units) and counts."""

    def __init__(self, points: np.ndarray, counts: np.ndarray):
        self.points, self.counts = points, counts

    @classmethod
    def empty(cls) -> LayerPolygons:
        return cls(np.zeros((0, 2), np.int64), np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.counts)

    @property
    def max_vertices(self) -> int:
        return int(self.counts.max(initial=0))

    def polygons(self) -> list[np.ndarray]:
        """Each polygon's (P, 2) vertices."""
        return np.split(self.points, np.cumsum(self.counts)[:-1]) if len(self.counts) else []


class LayoutFile:
    """One layout file of a mask set, GDSII or (``oasis``) OASIS, read with gdstk a few layers at a time."""

    def __init__(self, path: str | Path, oasis: bool = False):
        self.path = Path(path)
        self.kind = "OASIS" if oasis else "GDSII"
        self._oasis = None  # the whole OASIS library, read on first use

    def layers(self) -> set[tuple[int, int]]:
        """Every (layer, datatype) the file holds geometry on (a GDSII file's read without its geometry)."""
        import gdstk

        if self.kind == "GDSII":
            pairs = self._guard(lambda: gdstk.gds_info(str(self.path)))["layers_and_datatypes"]
        else:
            pairs = self._library(None).layers_and_datatypes()
        return {(int(a), int(b)) for a, b in pairs}

    def read(self, only: set) -> dict[tuple[int, int], LayerPolygons]:
        """Polygons of the (layer, datatype) pairs ``only`` that the file holds, in database units (1 nm)."""
        lib = self._library(only)
        tops = lib.top_level()
        if len(tops) != 1:
            raise CheckFailed(f"{self.path} must hold exactly one top cell, found {len(tops)}: export the set again")
        if abs(lib.precision * 1e9 - DBU_NM) > 1e-9:
            raise CheckFailed(f"{self.path} has a {lib.precision * 1e9:g} nm database unit, a mask set's is "
                              f"{DBU_NM} nm: export the set again")
        scale = lib.unit / lib.precision
        out = {}
        for layer, datatype in sorted(only):
            pts = [p.points for p in tops[0].get_polygons(layer=layer, datatype=datatype)]
            if pts:
                out[(layer, datatype)] = LayerPolygons(np.rint(np.concatenate(pts) * scale).astype(np.int64),
                                                       np.fromiter(map(len, pts), np.int64, len(pts)))
        return out

    def close(self) -> None:
        """Drop an OASIS file's reading (its memory)."""
        self._oasis = None

    def _library(self, only: set | None):
        import gdstk

        if self.kind == "GDSII":
            return self._guard(lambda: gdstk.read_gds(str(self.path), filter=only))
        if self._oasis is None:
            self._oasis = self._guard(lambda: gdstk.read_oas(str(self.path)))
        return self._oasis

    def _guard(self, read):
        try:
            return read()
        except Exception as exc:  # noqa: BLE001 - gdstk reports a damaged file as RuntimeError/OSError/...
            raise CheckFailed(f"{self.path} cannot be read as {self.kind} ({exc.__class__.__name__}: {exc}): the "
                              f"file is corrupt or truncated; export the set again") from None
