"""Mesh path: the recipe built with manifold3d (no OpenCascade), exported with trimesh."""

from __future__ import annotations

import numpy as np

from holder_cad.recipe import Body, Cone, Cyl, Prism, Revolve, Twisted

__all__ = ["build_manifold", "to_trimesh"]


def _solid(s, segments: int):
    from manifold3d import CrossSection, Manifold

    if isinstance(s, Cyl):
        m = Manifold.cylinder(s.z1 - s.z0, s.r, s.r, segments)
        return m.translate((s.x, s.y, s.z0))
    if isinstance(s, Cone):
        return Manifold.cylinder(s.z1 - s.z0, s.r0, s.r1, segments).translate((0, 0, s.z0))
    if isinstance(s, Revolve):
        return CrossSection([list(s.profile)]).revolve(segments)
    if isinstance(s, Prism):
        return CrossSection([list(s.points)]).extrude(s.z1 - s.z0).translate((0, 0, s.z0))
    if isinstance(s, Twisted):
        return _twisted_mesh(np.asarray(s.points, float), s.z0, s.z1, s.twist_deg)
    raise TypeError(f"unknown solid {s!r}")


def _twisted_mesh(points: np.ndarray, z0: float, z1: float, twist_deg: float):
    """Twisted prism of a star-shaped section as an explicit mesh whose facets follow the helix.

    manifold3d's twisted extrude splits each side quad along whichever diagonal it likes; on a thread flank
    that tilts facets by up to 25° from the true 45° surface. Here the z step equals the twist of one
    section step, so one diagonal of every quad follows the helix (constant radius) and every facet lies
    on the helicoidal flank.
    """
    from manifold3d import Manifold, Mesh

    n = len(points)
    r = np.hypot(points[:, 0], points[:, 1])
    theta = np.arctan2(points[:, 1], points[:, 0])
    if not np.allclose(np.diff(np.unwrap(theta)), 2 * np.pi / n, atol=1e-9):
        raise ValueError("twisted section must be sampled at equal angles, counter-clockwise")
    turns = twist_deg / 360.0
    steps = max(1, int(round(abs(turns) * n)))
    z = np.linspace(z0, z1, steps + 1)
    dth = np.deg2rad(twist_deg) / steps
    # vertex (k, i): section point i rotated by k·dth at height z_k; the radius follows the section point
    ang = theta[None, :] + dth * np.arange(steps + 1)[:, None]
    verts = np.stack([np.broadcast_to(r, ang.shape) * np.cos(ang), np.broadcast_to(r, ang.shape) * np.sin(ang),
                      np.broadcast_to(z[:, None], ang.shape)], axis=-1).reshape(-1, 3)
    k, i = np.meshgrid(np.arange(steps), np.arange(n), indexing="ij")
    a = k * n + i
    b = k * n + (i + 1) % n
    c = (k + 1) * n + i
    d = (k + 1) * n + (i + 1) % n
    # quad a-b (bottom row), c-d (top row); a→d is not a helix line, c→b is: since vertex (k+1, i) sits at the
    # angle of vertex (k, i+1) when dth equals the section step, split along b–c
    side = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
    nv = verts.shape[0]
    bottom_c, top_c = nv, nv + 1
    ring0 = np.arange(n)
    ringk = steps * n + np.arange(n)
    bottom = np.stack([np.full(n, bottom_c), (ring0 + 1) % n, ring0], -1)
    top = np.stack([np.full(n, top_c), ringk, steps * n + (np.arange(n) + 1) % n], -1)
    verts = np.vstack([verts, [[0, 0, z0], [0, 0, z1]]]).astype(np.float32)
    faces = np.concatenate([side, bottom, top]).astype(np.uint32)
    m = Manifold(Mesh(vert_properties=verts, tri_verts=faces))
    if m.is_empty() or m.volume() <= 0:
        raise ValueError(f"twisted mesh is not a valid solid ({m.status()})")
    return m


def build_manifold(body: Body, segments: int = 256):
    """manifold3d.Manifold of a recipe body."""
    from manifold3d import Manifold

    adds = Manifold.batch_boolean([_solid(s, segments) for s in body.adds], _op("Add"))
    if not body.subs:
        return adds
    subs = Manifold.batch_boolean([_solid(s, segments) for s in body.subs], _op("Add"))
    return adds - subs


def _op(name):
    from manifold3d import OpType

    return getattr(OpType, name)


def to_trimesh(manifold):
    import trimesh

    mesh = manifold.to_mesh()
    verts = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(mesh.tri_verts, dtype=np.int64)
    return trimesh.Trimesh(verts, faces, process=False)
