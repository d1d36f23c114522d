"""B-rep path: the same recipe built with cadquery (OpenCascade) for STEP; imported only when used."""

from __future__ import annotations

from pathlib import Path

from holder_cad.params import HolderParams
from holder_cad.recipe import Body, Cone, Cyl, Prism, Revolve, Twisted, base_body, cartridge_body

__all__ = ["build_brep", "export_step", "body_solid"]


def _solid(s):
    import cadquery as cq

    if isinstance(s, Cyl):
        return cq.Solid.makeCylinder(s.r, s.z1 - s.z0, cq.Vector(s.x, s.y, s.z0))
    if isinstance(s, Cone):
        return cq.Solid.makeCone(s.r0, s.r1, s.z1 - s.z0, cq.Vector(0, 0, s.z0))
    if isinstance(s, Revolve):
        wp = cq.Workplane("XZ").polyline([tuple(map(float, q)) for q in s.profile]).close()
        return wp.revolve(360.0, (0, 0, 0), (0, 1, 0)).val()
    if isinstance(s, Prism):
        wp = cq.Workplane("XY").workplane(offset=s.z0).polyline([tuple(map(float, q)) for q in s.points]).close()
        return wp.extrude(s.z1 - s.z0).val()
    if isinstance(s, Twisted):  # a periodic spline through the section points: one smooth helicoidal face
        pts = [tuple(map(float, q)) for q in s.points]
        wp = cq.Workplane("XY").workplane(offset=s.z0).spline(pts, periodic=True).close()
        return wp.twistExtrude(s.z1 - s.z0, s.twist_deg).val()
    raise TypeError(f"unknown solid {s!r}")


def body_solid(body: Body):
    """cadquery Solid of a recipe body (adds fused, subs cut)."""
    adds = [_solid(s) for s in body.adds]
    shape = adds[0].fuse(*adds[1:]) if len(adds) > 1 else adds[0]
    if body.subs:
        shape = shape.cut(*[_solid(s) for s in body.subs])
    return shape.clean()


def build_brep(p: HolderParams) -> dict:
    """B-rep solids of the base and the cartridge in print orientation."""
    return {"base": body_solid(base_body(p)), "cartridge": body_solid(cartridge_body(p))}


def export_step(solids: dict, path: str | Path, gap: float = 5.0) -> None:
    """One STEP file with both bodies laid out side by side (as in holder.stl), written atomically."""
    import tempfile

    import cadquery as cq

    from doefab.io import atomic_write_bytes

    placed, x = [], 0.0
    for s in solids.values():
        bb = s.BoundingBox()
        placed.append(s.translate(cq.Vector(x - bb.xmin, -0.5 * (bb.ymin + bb.ymax), -bb.zmin)))
        x += bb.xlen + gap
    compound = cq.Compound.makeCompound(placed)
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp) / "holder.step"
        cq.exporters.export(compound, str(tmp_path))
        atomic_write_bytes(path, tmp_path.read_bytes())
