"""The mask layer map (one place): GDS layer numbers, purposes and which plate each belongs to."""

from __future__ import annotations

from doefab.fabrication.process import MAX_MASKS

__all__ = ["ETCH_LAYERS", "CHROME_LAYER", "KEY_LAYER", "VERNIER_LAYER", "LABEL_LAYER", "OUTLINE_LAYER",
           "etch_layer", "etch_bit", "LAYER_PURPOSES"]

# etch mask for 2^bit·d, bit = 0..4: layers 1..4 as in every 16-level set, then 6 (layer 5 is the chrome plate's)
ETCH_LAYERS = (1, 2, 3, 4, 6)
CHROME_LAYER = 5
KEY_LAYER = 10  # datatype = plate (0 chrome, 1..M etch masks)
VERNIER_LAYER = 11  # datatype = plate: verniers and CD ladder
LABEL_LAYER = 63  # reserved for labels (not written)
OUTLINE_LAYER = 100

LAYER_PURPOSES = {
    CHROME_LAYER: "chrome aperture / baffle: chrome remains where polygons are (opaque outside the clear "
                  "aperture; clear slits on the y axis mark the split line x = 0)",
    KEY_LAYER: "alignment keys (crosses) and, on etch plates, clear windows over the keys they align to; "
               "datatype = plate",
    VERNIER_LAYER: "verniers (each plate's scale against the reference scale on the plate it aligns to; bar "
                   "width, pitches and reading step in the manifest's verniers) and a CD ladder (1, 1.5, 2, 3 × CD); "
                   "datatype = plate",
    LABEL_LAYER: "labels (reserved, not written)",
    OUTLINE_LAYER: "die outline",
}


def etch_layer(bit: int) -> int:
    """GDS layer of the etch mask for 2^bit·d (its plate is bit + 1)."""
    if not isinstance(bit, int) or not 0 <= bit < MAX_MASKS:
        raise ValueError(f"bit must be 0..{MAX_MASKS - 1}")
    return ETCH_LAYERS[bit]


def etch_bit(layer: int) -> int:
    """The bit (2^bit·d) of etch layer ``layer``; ValueError for a layer that is not an etch layer."""
    if layer not in ETCH_LAYERS:
        raise ValueError(f"layer {layer!r} is not an etch layer ({', '.join(map(str, ETCH_LAYERS))})")
    return ETCH_LAYERS.index(layer)
