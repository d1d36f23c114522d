"""Training depth layouts with slanted and curved surfaces: only the training split draws them, their planes
project as planes do, curved objects come toward the camera, and they reach the near end of the range."""

import numpy as np

from doefab.reconstruction import data, depthlayouts
from doefab.reconstruction.data import depth_sample, sample_rng


def _flat_texture(r):
    return np.full((3, 64, 64), 0.5, np.float32)


def test_only_the_training_split_draws_world_layouts(monkeypatch):
    before = {s: depth_sample(sample_rng(s, 2), 48, s) for s in ("train", "val", "test", "final")}
    monkeypatch.setattr(data, "WORLD_SHARE", 1.0)
    after = {s: depth_sample(sample_rng(s, 2), 48, s) for s in ("train", "val", "test", "final")}
    for s in ("val", "test", "final"):  # held-out scenes stay bit for bit what they were
        np.testing.assert_array_equal(before[s][1], after[s][1])
        np.testing.assert_array_equal(before[s][0], after[s][0])
    assert not np.array_equal(before["train"][1], after["train"][1])


def test_a_slanted_plane_is_affine_in_inverse_depth():
    # a plane seen through a pinhole: 1/z = a + b·x + c·y across the image, so second differences vanish
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[:32, :32] / 31 - 0.5
    inv = depthlayouts._plane(rng, xx, yy, 0.5, 0.8, 0.0, 10.0)  # bounds wide enough that nothing clips
    assert np.abs(np.diff(inv, 2, axis=0)).max() < 1e-12 and np.abs(np.diff(inv, 2, axis=1)).max() < 1e-12
    assert np.ptp(inv) > 0.01  # and it is slanted


def test_layouts_stay_in_range_and_reach_near_surfaces():
    near = []
    for seed in range(40):
        scene, depth = depthlayouts.world_layout(np.random.default_rng(seed), 64, 1.0, 5.0, _flat_texture)
        assert scene.shape == (3, 64, 64) and depth.shape == (64, 64)
        assert depth.min() >= 1.0 - 1e-6 and depth.max() <= 5.0 + 1e-6
        near.append((depth < 1.5).mean())
    # objects evenly in inverse depth: a third of them nearer than 1.5 m (1/1.5 is 5/12 of the way from 1/5 to 1)
    assert np.mean(near) > 0.1


def test_a_dome_rises_from_the_outline_to_the_middle():
    m = np.zeros((21, 21), bool)
    m[3:18, 3:18] = True
    d = depthlayouts._dome(m)
    assert d[10, 10] == 1.0 and d[3, 10] < 0.5 and d[~m].max() == 0.0
    assert not depthlayouts._dome(np.zeros((5, 5), bool)).any()
