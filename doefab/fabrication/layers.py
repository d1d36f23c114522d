"""The mask layer map (one place): GDS layer numbers, purposes and which plate each belongs to."""

from __future__ import annotations

from doefab.fabrication.bitplanes import N_MASKS

__all__ = ["ETCH_LAYER", "CHROME_LAYER", "KEY_LAYER", "VERNIER_LAYER", "LABEL_LAYER", "OUTLINE_LAYER",
           "etch_layer", "LAYER_PURPOSES"]

ETCH_LAYER = 1  # layers 1..4: etch masks for 2^0·d … 2^3·d
CHROME_LAYER = 5
KEY_LAYER = 10  # datatype = plate (0 chrome, 1..4 etch masks)
VERNIER_LAYER = 11  # datatype = plate: verniers and CD ladder
LABEL_LAYER = 63  # reserved for labels (not written)
OUTLINE_LAYER = 100

LAYER_PURPOSES = {
    CHROME_LAYER: "chrome aperture / baffle: chrome remains where polygons are (opaque outside the clear "
                  "aperture; clear slits on the y axis mark the split line x = 0)",
    KEY_LAYER: "alignment keys (crosses) and, on etch plates, clear windows over the keys they align to; "
               "datatype = plate",
    VERNIER_LAYER: "verniers (reference pitch 20 µm on the chrome plate, 22 µm on etch plates) and a CD ladder "
                   "(1, 1.5, 2, 3 × CD); datatype = plate",
    LABEL_LAYER: "labels (reserved, not written)",
    OUTLINE_LAYER: "die outline",
}


def etch_layer(bit: int) -> int:
    """GDS layer of the etch mask for 2^bit·d."""
    if not 0 <= bit < N_MASKS:
        raise ValueError(f"bit must be 0..{N_MASKS - 1}")
    return ETCH_LAYER + bit
