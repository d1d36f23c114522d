"""PNG renders of the assembled holder from three views (matplotlib, coarse mesh, flat shading)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from holder_cad.params import HolderParams

__all__ = ["render_views"]

# name: (elevation, azimuth, half-section?, axis seen edge-on) — the side view is cut along the y = 0 plane to
# show the inside; an axis seen edge-on gets no ticks or label (they would pile up on each other)
VIEWS = {"render_front.png": (90, -90, False, "z"), "render_side.png": (5, -90, True, "y"),
         "render_iso.png": (30, -60, False, None)}


def render_views(p: HolderParams, asm: list, out: Path) -> list[str]:
    """Write the three views of ``asm`` (the assembled base and cartridge, manifold3d meshes: a coarse build of
    ``p`` is enough) into ``out``; return the file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    colors = ["#4878cf", "#d65f5f"]
    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)
    names = []
    zmin = min(m.bounding_box()[2] for m in asm)
    zmax = max(m.bounding_box()[5] for m in asm)
    for fname, (elev, azim, cut, edge_on) in VIEWS.items():
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(111, projection="3d")
        shown = [m.trim_by_plane((0.0, 1.0, 0.0), 0.0) for m in asm] if cut else asm
        for m, col in zip(shown, colors):
            mesh = m.to_mesh()
            v = np.asarray(mesh.vert_properties)[:, :3]
            tri = v[np.asarray(mesh.tri_verts)]
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
            shade = 0.35 + 0.65 * np.clip(n @ light, 0, 1)
            base = np.array(matplotlib.colors.to_rgb(col))
            pc = Poly3DCollection(tri, facecolors=shade[:, None] * base[None, :], edgecolors="none")
            ax.add_collection3d(pc)
        r = p.flange_diameter_mm / 2
        ax.set_xlim(-r, r)
        ax.set_ylim(-r, r)
        ax.set_zlim(zmin, zmax)
        ax.set_box_aspect((2 * r, 2 * r, max(zmax - zmin, 1.0)))
        ax.view_init(elev=elev, azim=azim)
        labels = {"x": "x (mm)", "y": "y (mm)", "z": "z (mm)"}
        for axis, label in labels.items():
            if axis == edge_on:
                getattr(ax, f"set_{axis}ticks")([])
                getattr(ax, f"set_{axis}label")("")
            else:
                getattr(ax, f"set_{axis}label")(label, labelpad=12 if axis == "x" else 8)
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
