"""holder_cad: the parametric 3D-printable DOE holder (millimetres, the CAD convention)."""
