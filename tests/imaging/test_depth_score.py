"""The network-free depth-encoding score, checked against a pixel-domain computation and limiting cases."""

import math

import numpy as np
import pytest
import torch

from doefab.errors import DoefabError
from doefab.imaging.depth_score import depth_encoding_score


def _gauss(k, sigma):
    c = np.arange(k) - k // 2
    g = np.exp(-(c[None, :] ** 2 + c[:, None] ** 2) / (2 * sigma**2))
    return 0.5 * g / g.sum()


def test_white_texture_matches_parseval_in_the_pixel_domain():
    """For a white texture the difference-image energy is the pixel-domain Σ (ΔP)² (minus its mean): an
    independent computation of E, and so of d'."""
    k, widths = 21, (1.0, 2.0, 3.5)
    psf = torch.from_numpy(np.stack([_gauss(k, s) for s in widths])[:, None])
    out = depth_encoding_score(psf, [1.0, 2.0, 3.0], spectrum="white", contrast=0.1, patch=8, signal=0.25)
    n = 2 * k
    sigma = math.sqrt(0.25 * 25_000 + 9) / 25_000
    for i in range(2):
        d = np.zeros((n, n))
        d[:k, :k] = _gauss(k, widths[i]) - _gauss(k, widths[i + 1])
        energy = 0.01 * (np.sum(d**2) - d.sum() ** 2 / n**2) * n**2 / (n**2 - 1)
        assert out["dprime"][i] == pytest.approx(math.sqrt(64 * energy) / sigma, rel=1e-6)


def test_identical_planes_cannot_be_told_apart_and_distinct_ones_can():
    same = torch.from_numpy(np.stack([_gauss(21, 2.0)] * 3)[:, None])
    out = depth_encoding_score(same, [1.0, 2.0, 3.0])
    assert out["min_dprime"] == 0.0
    assert out["predicted_error_m"] == pytest.approx(0.5 * 2.0 / 3)  # chance confusion × step, per plane
    apart = torch.from_numpy(np.stack([_gauss(31, s) for s in (0.7, 3.0, 8.0)])[:, None])
    better = depth_encoding_score(apart, [1.0, 2.0, 3.0])
    assert better["predicted_error_m"] < 0.1 * out["predicted_error_m"] and better["min_dprime"] > 2


def test_order_of_depths_does_not_matter_and_bad_shapes_are_refused():
    psf = torch.from_numpy(np.stack([_gauss(15, s) for s in (1.0, 2.0, 4.0)])[:, None])
    a = depth_encoding_score(psf, [1.0, 2.0, 3.0])
    b = depth_encoding_score(psf.flip(0), [3.0, 2.0, 1.0])
    assert a["dprime"] == pytest.approx(b["dprime"])
    with pytest.raises(DoefabError, match="one PSF per depth"):
        depth_encoding_score(psf, [1.0, 2.0])
    with pytest.raises(DoefabError, match="wavelengths, K, K"):
        depth_encoding_score(psf[0], [1.0])
