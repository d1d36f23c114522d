"""Cross-blur cost volume: zero at the true plane of a fronto-parallel scene, and a clear error on bad shapes."""

import pytest
import torch

from doefab.errors import DoefabError
from doefab.imaging.captures import convolve
from doefab.reconstruction.costvolume import cross_blur_cost, relative_log_cost


def _psfs(d, k, seed):
    g = torch.Generator().manual_seed(seed)
    p = torch.rand(d, 3, k, k, generator=g, dtype=torch.float64) ** 4  # distinct, lumpy kernels per plane
    return p / p.sum(dim=(-2, -1), keepdim=True)


@pytest.mark.parametrize("plane", [0, 2, 4])
def test_cost_vanishes_at_the_true_plane_and_not_elsewhere(plane):
    k, size, margin = 11, 96, 16
    pc, pu = _psfs(5, k, 1), _psfs(5, k, 2)
    scene = torch.rand(1, 3, size + 2 * margin, size + 2 * margin, generator=torch.Generator().manual_seed(3),
                       dtype=torch.float64)
    # captures of a fronto-parallel textured plane, rendered with a margin so the crop holds all its light
    crop = (slice(None), slice(None), slice(margin, margin + size), slice(margin, margin + size))
    c = convolve(scene, pc[plane])[crop]
    u = convolve(scene, pu[plane])[crop]
    cost = cross_blur_cost(c, u, pc, pu, window=5)
    assert cost.shape == (1, 5, size, size)
    inner = cost[0, :, k + 2:-k - 2, k + 2:-k - 2]  # away from the crop's border (edge replication there)
    wrong = torch.cat([inner[:plane], inner[plane + 1:]])
    assert float(inner[plane].max()) < 1e-20  # p_u ∗ c − p_c ∗ u = 0 to float64 precision at the true plane
    assert float(wrong.min()) > 1e-6  # and every other plane leaves a residual on this texture
    assert bool((cost[0].argmin(dim=0)[k + 2:-k - 2, k + 2:-k - 2] == plane).all())


def test_relative_log_cost_ignores_scene_contrast():
    pc, pu = _psfs(3, 7, 4), _psfs(3, 7, 5)
    c, u = torch.rand(1, 3, 64, 64, dtype=torch.float64), torch.rand(1, 3, 64, 64, dtype=torch.float64)
    a = relative_log_cost(cross_blur_cost(c, u, pc, pu), eps=0.0)
    b = relative_log_cost(cross_blur_cost(3 * c, 3 * u, pc, pu), eps=0.0)  # 3× brighter: cost 9× larger
    assert torch.allclose(a, b, atol=1e-9)
    assert torch.allclose(a.mean(dim=1), torch.zeros(1, 64, 64, dtype=torch.float64), atol=1e-9)


def test_cost_is_differentiable_in_the_psf():
    pc, pu = _psfs(3, 7, 6).requires_grad_(True), _psfs(3, 7, 7)
    c, u = torch.rand(1, 3, 64, 64, dtype=torch.float64), torch.rand(1, 3, 64, 64, dtype=torch.float64)
    cross_blur_cost(c, u, pc, pu).mean().backward()
    assert pc.grad is not None and float(pc.grad.abs().sum()) > 0


@pytest.mark.parametrize("c_shape, p_shape, window, match", [
    ((1, 3, 64, 64), (3, 1, 7, 7), 9, "PSFs must be"),
    ((3, 64, 64), (3, 3, 7, 7), 9, "captures must be"),
    ((1, 3, 64, 64), (3, 3, 7, 7), 4, "odd"),
])
def test_bad_shapes_are_refused(c_shape, p_shape, window, match):
    with pytest.raises(DoefabError, match=match):
        cross_blur_cost(torch.rand(*c_shape), torch.rand(*c_shape), torch.rand(*p_shape), torch.rand(*p_shape), window)
