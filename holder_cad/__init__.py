"""holder_cad: the parametric 3D-printable DOE holder (millimetres, the CAD convention).

Mesh path (manifold3d + trimesh, default) and B-rep path (cadquery, for STEP) evaluate one recipe.
Heavy packages load only when a function that needs them runs.
"""

from holder_cad.params import HolderError, HolderParams

__all__ = ["HolderParams", "HolderError", "build_parts", "write_holder"]


def build_parts(p):
    from holder_cad.build import build_parts as _b

    return _b(p)


def write_holder(p, out_dir, **kw):
    from holder_cad.build import write_holder as _w

    return _w(p, out_dir, **kw)
