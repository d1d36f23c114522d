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
