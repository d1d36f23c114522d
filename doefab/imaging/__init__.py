"""Image formation: sensor response, capture simulation (the paper's Eq. 11, 14, 23, 27) and dual-pixel crosstalk."""
