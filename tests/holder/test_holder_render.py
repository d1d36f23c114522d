"""The holder's PNG views draw only the faces turned toward the viewer, split small enough for matplotlib's
depth sort: checked on a cube, whose visible area and normals are known."""

import numpy as np


def _area(tri: np.ndarray) -> float:
    return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


def test_a_cube_seen_from_above_shows_its_top_face_only_in_small_triangles():
    import manifold3d

    from holder_cad.render import _view_direction, facing_triangles

    cube = manifold3d.Manifold.cube((10.0, 10.0, 10.0), True).to_mesh()
    up = _view_direction(90, -90)
    assert np.allclose(up, [0, 0, 1], atol=1e-12)
    tri, n = facing_triangles(cube, up, 1.5)
    assert abs(_area(tri) - 100.0) < 1e-9  # the top face, 10 mm × 10 mm, and nothing else
    assert np.allclose(n, [0, 0, 1]) and np.allclose(tri[..., 2], 5.0)
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
    assert edges.max() <= 1.5 + 1e-9 and len(tri) >= 2 * (10 / 1.5) ** 2
    # from the iso view's corner direction three faces show, 300 mm²
    iso, _ = facing_triangles(cube, np.array([1.0, -1.0, 1.0]) / np.sqrt(3), 20.0)
    assert abs(_area(iso) - 300.0) < 1e-9 and len(iso) == 6


def test_the_culling_direction_is_the_direction_matplotlib_views_from():
    """Each view's ``_view_direction`` points at matplotlib's viewer: a step along it brings a point nearer in
    matplotlib's own projection and leaves it on the same screen spot (orthographic), a step across it does not
    change its depth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d import proj3d

    from holder_cad.render import VIEWS, _view_direction, view_axes

    for elev, azim, _, _ in VIEWS.values():
        fig = plt.figure()
        ax = view_axes(fig, 20.0, 0.0, 10.0, elev, azim)
        fig.canvas.draw()
        d = _view_direction(elev, azim)
        across = np.cross(d, [0.3, 0.5, 0.8])
        p0 = np.array([5.0, 7.0, 3.0])
        pts = np.array([p0, p0 + 4 * d, p0 + 4 * across / np.linalg.norm(across)])
        x, y, z = proj3d.proj_transform(*pts.T, ax.get_proj())
        plt.close(fig)
        assert z[1] < z[0] - 1e-3, (elev, azim)  # nearer
        assert abs(x[1] - x[0]) < 1e-9 and abs(y[1] - y[0]) < 1e-9, (elev, azim)  # the same spot: orthographic
        assert abs(z[2] - z[0]) < 1e-9, (elev, azim)


def test_split_triangles_keep_their_own_faces_normals():
    import manifold3d

    from holder_cad.render import facing_triangles

    cube = manifold3d.Manifold.cube((10.0, 10.0, 10.0), True).to_mesh()
    tri, n = facing_triangles(cube, np.array([1.0, -1.0, 1.0]) / np.sqrt(3), 1.5)
    assert len(tri) == len(n) and len(tri) > 3 * 2 * (10 / 1.5) ** 2
    own = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.allclose(own / np.linalg.norm(own, axis=1, keepdims=True), n)
    assert {tuple(v) for v in np.round(n).astype(int)} == {(1, 0, 0), (0, -1, 0), (0, 0, 1)}
