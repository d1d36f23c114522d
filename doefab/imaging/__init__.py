"""Image formation: sensor response, capture simulation (seed Eq. 11, 14, 23, 27) and dual-pixel crosstalk."""
