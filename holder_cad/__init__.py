"""holder_cad: the parametric 3D-printable DOE holder (millimetres, the CAD convention).

Mesh path (manifold3d + trimesh, default) and B-rep path (cadquery, for STEP) evaluate one recipe.
Heavy packages load only when a function that needs them runs.
"""

from holder_cad.params import HolderError, HolderParams

__all__ = ["HolderParams", "HolderError", "build_parts", "write_holder"]


def build_parts(p):
    """Manifolds of the two printed bodies (``"base"``, ``"cartridge"``) for :class:`HolderParams` ``p``
    (millimetres), each in its print orientation on the bed at z = 0; no checks are run."""
    from holder_cad.build import build_parts as _b

    return _b(p)


def write_holder(p, out_dir, **kw):
    """Build and check the holder for :class:`HolderParams` ``p`` (millimetres) and write it to ``out_dir``.

    Writes ``holder.stl``, ``holder.3mf``, ``coupon.stl`` (a fit-test ring and die pocket), ``holder.step``
    (``step=True``, or by default when cadquery is installed), renders (``renders=True``) and ``holder.json``
    (parameters, every check with its value and limit in mm, the files). A part that fails a check gets no
    printable file: ``holder.FAILED.json`` holds the report and ``HolderError`` names the failing quantities.

    Args:
        p: the parameters (every length in millimetres).
        out_dir: output folder (created if needed).
        step: write STEP through cadquery (True/False; None = when cadquery is installed).
        renders: write PNG renders of the assembled holder.
    Returns:
        The report written to ``holder.json``.
    """
    from holder_cad.build import write_holder as _w

    return _w(p, out_dir, **kw)
