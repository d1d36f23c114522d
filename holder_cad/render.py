"""PNG renders of the assembled holder from three views (matplotlib, coarse mesh, flat shading).

matplotlib draws a 3-D collection by the painter's algorithm: each triangle whole, in the order of its mean
depth. A flat face's long fan triangles (a wide flange's annulus: 75 mm spokes) then sort wrongly against the
smaller ones below them and show as streaks. So the views are orthographic, the faces turned away from the viewer
(never visible on a closed mesh) are dropped, and the rest are split to at most ``MAX_EDGE_FRACTION`` of the
flange's diameter (``trimesh.remesh.subdivide_to_size``) before they are sorted, all parts in one collection.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from holder_cad.params import HolderParams

__all__ = ["render_views"]

# name: (elevation, azimuth, half-section?, axis seen edge-on) — the side view is cut along the y = 0 plane to
# show the inside; an axis seen edge-on gets no ticks or label (they would pile up on each other)
VIEWS = {"render_front.png": (90, -90, False, "z"), "render_side.png": (5, -90, True, "y"),
         "render_iso.png": (30, -60, False, None)}
MAX_EDGE_FRACTION = 0.04  # of the flange's diameter: the longest triangle edge drawn


def _view_direction(elev: float, azim: float) -> np.ndarray:
    """Unit vector from the scene toward an orthographic viewer at ``elev``, ``azim`` degrees (matplotlib's)."""
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def facing_triangles(mesh, toward: np.ndarray, max_edge: float) -> tuple[np.ndarray, np.ndarray]:
    """(triangles [T, 3, 3] mm, unit normals [T, 3]) of a manifold3d mesh's faces turned toward ``toward`` (a unit
    vector to the viewer; faces seen edge-on are dropped too), each split until no edge is longer than ``max_edge``
    (mm).

    Example: a 10 mm cube's ``facing_triangles(cube.to_mesh(), np.array([0, 0, 1.0]), 1.5)`` is its top face in
    triangles of at most 1.5 mm edges, 100 mm² in all."""
    import trimesh

    v = np.asarray(mesh.vert_properties)[:, :3].astype(np.float64)
    f = np.asarray(mesh.tri_verts)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    front = n @ toward > 1e-6  # edge-on faces (a wall seen from straight above) cover no area
    v2, f2, idx = trimesh.remesh.subdivide_to_size(v, f[front], max_edge, return_index=True)
    return v2[f2], n[front][idx]


def _collection(parts: list, toward: np.ndarray, max_edge: float):
    """One ``Poly3DCollection`` of every part's facing triangles, flat-shaded in the part's colour (base blue,
    cartridge red). One for all: matplotlib sorts the triangles within a collection by depth, but whole collections
    only by their nearest point, which painted all of the cartridge over the base."""
    import matplotlib.colors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    tris, rgbs = [], []
    for m, col in zip(parts, ("#4878cf", "#d65f5f")):
        tri, n = facing_triangles(m.to_mesh(), toward, max_edge)
        tris.append(tri)
        rgbs.append((0.35 + 0.65 * np.clip(n @ light, 0, 1))[:, None] * np.array(matplotlib.colors.to_rgb(col)))
    rgb = np.concatenate(rgbs)
    # edges in the face colour: antialiased seams between the split triangles would show the background
    return Poly3DCollection(np.concatenate(tris), facecolors=rgb, edgecolors=rgb, linewidths=0.3)


def view_axes(fig, r: float, zmin: float, zmax: float, elev: float, azim: float):
    """3-D axes over x, y in [−r, r] and z in [zmin, zmax] (mm) at one scale, seen orthographically from ``elev``,
    ``azim`` degrees: the view ``_view_direction`` culls for."""
    ax = fig.add_subplot(111, projection="3d")
    ax.set_proj_type("ortho")
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_zlim(zmin, zmax)
    ax.set_box_aspect((2 * r, 2 * r, zmax - zmin))
    ax.view_init(elev=elev, azim=azim)
    return ax


def render_views(p: HolderParams, asm: list, out: Path) -> list[str]:
    """Write the three views of ``asm`` (the assembled base and cartridge, manifold3d meshes: a coarse build of
    ``p`` is enough) into ``out``; return the file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = []
    zmin = min(m.bounding_box()[2] for m in asm)
    zmax = max(max(m.bounding_box()[5] for m in asm), zmin + 1.0)  # axes in proportion: the culling's view
    for fname, (elev, azim, cut, edge_on) in VIEWS.items():
        fig = plt.figure(figsize=(6, 5))
        ax = view_axes(fig, p.flange_diameter_mm / 2, zmin, zmax, elev, azim)
        shown = [m.trim_by_plane((0.0, 1.0, 0.0), 0.0) for m in asm] if cut else asm
        ax.add_collection3d(_collection(shown, _view_direction(elev, azim), MAX_EDGE_FRACTION * p.flange_diameter_mm))
        labels = {"x": "x (mm)", "y": "y (mm)", "z": "z (mm)"}
        for axis, label in labels.items():
            if axis == edge_on:
                getattr(ax, f"set_{axis}ticks")([])
                getattr(ax, f"set_{axis}label")("")
            else:
                getattr(ax, f"set_{axis}label")(label, labelpad=(20 if cut else 12) if axis == "x" else 8)
        if edge_on != "z":  # a short z range: three ticks, so the labels do not pile up
            ax.set_zticks(np.round(np.linspace(zmin, zmax, 3), 1))
        ax.tick_params(labelsize=7)
        what = "half section, base blue, cartridge red" if cut else "base blue, cartridge red"
        ax.set_title(f"DOE holder ({p.mount} mount), {fname[7:-4]} view\n({what}; +z toward the scene)", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=100)
        plt.close(fig)
        names.append(fname)
    return names
