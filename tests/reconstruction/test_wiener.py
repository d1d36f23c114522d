import numpy as np
import pytest
import torch

from doefab.errors import DoefabError
from doefab.reconstruction.wiener import WienerDeconvolution, psf_to_otf, wiener_deconvolve


def _gauss(k, sigma):
    y, x = np.mgrid[:k, :k] - k // 2
    g = np.exp(-(x**2 + y**2) / (2 * sigma**2))
    return torch.from_numpy(g / g.sum()).float()


def _circular_blur(img, psf):
    otf = psf_to_otf(psf, img.shape[-2:])
    return torch.fft.irfft2(torch.fft.rfft2(img) * otf, s=img.shape[-2:])


def test_recovers_a_known_blurred_image():
    rng = np.random.default_rng(0)
    # a smooth periodic test image (band-limited so the Gaussian's OTF is far from zero where it has energy)
    yy, xx = np.mgrid[:64, :64] / 64
    img = torch.from_numpy(0.5 + 0.2 * np.sin(2 * np.pi * 3 * xx) * np.cos(2 * np.pi * 2 * yy)
                           + 0.1 * np.cos(2 * np.pi * (xx + 2 * yy))).double()[None, None]
    psf = _gauss(9, 1.2).double()[None, None]
    blurred = _circular_blur(img, psf)
    # the layer pads by replication (for real, non-periodic images); on this periodic test image use the
    # plain circular Wiener filter the layer implements, by deconvolving a 3×3 tiling and taking the centre
    tiled = blurred.repeat(1, 1, 3, 3)
    rec = wiener_deconvolve(tiled, psf, 1e-8)[..., 64:128, 64:128]
    err = float((rec - img).norm() / img.norm())
    assert err < 1e-3, err
    del rng


def test_finite_for_a_psf_with_spectral_zeros():
    psf = torch.zeros(1, 1, 9, 9)
    psf[0, 0, 4, 2:7] = 1 / 5  # a 5-pixel box: its OTF has exact zeros
    img = torch.rand(1, 1, 40, 40)
    y = _circular_blur(img, psf)
    for lam in (1e-6, 1e-3, 1e-1):
        out = wiener_deconvolve(y, psf, lam)
        assert bool(torch.isfinite(out).all())
        # per frequency |K| / (|K|² + λ) ≤ 1 / (2√λ), so by Parseval ‖x‖ ≤ ‖y_padded‖ / (2√λ)
        y_pad = torch.nn.functional.pad(y, (5, 5, 5, 5), mode="replicate")
        assert float(out.norm()) <= float(y_pad.norm()) / (2 * lam**0.5) + 1e-6


def test_learned_lambda_layer_has_gradients():
    layer = WienerDeconvolution(3, lam0=0.05)
    assert torch.allclose(layer.lam, torch.full((3,), 0.05), atol=1e-5)
    y = torch.rand(2, 3, 32, 32, requires_grad=True)
    psf = _gauss(7, 1.0)[None, None].repeat(2, 3, 1, 1)
    out = layer(y, psf)
    assert out.shape == y.shape
    out.sum().backward()
    assert layer.theta.grad is not None and y.grad is not None and bool(torch.isfinite(layer.theta.grad).all())


def test_bad_inputs():
    with pytest.raises(DoefabError, match="positive"):
        wiener_deconvolve(torch.rand(1, 1, 8, 8), _gauss(3, 1)[None, None], 0.0)
    with pytest.raises(DoefabError, match="B, C, H, W"):
        wiener_deconvolve(torch.rand(8, 8), _gauss(3, 1)[None, None], 0.1)


def test_each_feature_with_each_psf_matches_pair_by_pair_deconvolution():
    # three features, two PSFs of different widths and offsets (one per batch item, or one for the whole batch),
    # a λ per output channel: output channel c·F + f is feature f deconvolved with PSF c under λ[c·F + f], and the
    # gradients are those of the pair-by-pair computation
    torch.manual_seed(0)
    psf2 = torch.stack([torch.stack([_gauss(7, s), torch.roll(_gauss(7, s + 0.5), 1, -1)]) for s in (0.8, 1.4)])
    for psf in (psf2.double(), psf2[:1].double()):
        y = torch.rand(2, 3, 24, 20, dtype=torch.float64, requires_grad=True)
        lam = torch.tensor([1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2], dtype=torch.float64, requires_grad=True)
        weight = torch.rand(2, 6, 24, 20, dtype=torch.float64)
        got = wiener_deconvolve(y, psf, lam, each=True)
        assert got.shape == (2, 6, 24, 20)
        grads = torch.autograd.grad((got * weight).sum(), (y, lam))
        want = torch.cat([wiener_deconvolve(y[:, f:f + 1], psf[:, c:c + 1], lam[c * 3 + f])
                          for c in range(2) for f in range(3)], dim=1)
        torch.testing.assert_close(got, want, rtol=0, atol=1e-12)
        for g, w in zip(grads, torch.autograd.grad((want * weight).sum(), (y, lam))):
            torch.testing.assert_close(g, w, rtol=1e-10, atol=1e-12)


def test_coded_features_deconvolve_raw_channels_with_their_colour_and_features_with_every_psf():
    from doefab.reconstruction.networks import CodedFeatures

    torch.manual_seed(1)
    for raw, n_psf in ((True, 3), (False, 4)):
        layer = CodedFeatures(n_psf, 2, raw=raw).double()
        with torch.no_grad():
            layer.wiener.theta.copy_(torch.linspace(-6.0, -2.0, layer.channels))
        coded = torch.rand(1, 3, 20, 20, dtype=torch.float64)
        psf = torch.stack([_gauss(5, 0.6 + 0.3 * c) for c in range(n_psf)])[None].double()
        got = layer(coded, psf)
        f, lam = layer.feat_coded(coded), layer.wiener.lam
        want = [wiener_deconvolve(coded[:, c:c + 1], psf[:, c:c + 1], lam[c]) for c in range(3 if raw else 0)]
        off = 3 if raw else 0
        want += [wiener_deconvolve(f[:, j:j + 1], psf[:, c:c + 1], lam[off + 2 * c + j])
                 for c in range(n_psf) for j in range(2)]
        torch.testing.assert_close(got, torch.cat(want, dim=1), rtol=0, atol=1e-12)


def test_coded_features_reuse_a_filter_only_for_the_same_psf_lambda_and_size():
    """Without autograd the layer keeps the Wiener filter of the last PSF and λ: every call must still give the
    deconvolution of the PSF and λ it is called with (computed afresh here), when the PSF changes in place, when λ
    changes, and when the image size changes."""
    from doefab.reconstruction.networks import CodedFeatures

    torch.manual_seed(2)
    layer = CodedFeatures(3, 2, raw=True).double().eval()
    psf = torch.stack([_gauss(5, 0.6 + 0.3 * c) for c in range(3)])[None].double()
    other = torch.stack([_gauss(5, 1.4 - 0.2 * c) for c in range(3)])[None].double()

    def fresh(coded, p):
        f, lam = layer.feat_coded(coded), layer.wiener.lam
        return torch.cat([wiener_deconvolve(coded, p, lam[:3]), wiener_deconvolve(f, p, lam[3:], each=True)], dim=1)

    coded = torch.rand(1, 3, 20, 24, dtype=torch.float64)
    with torch.no_grad():
        for _ in range(2):
            torch.testing.assert_close(layer(coded, psf), fresh(coded, psf), rtol=0, atol=0)
        psf.copy_(other)  # another PSF in the very tensor the layer was called with
        torch.testing.assert_close(layer(coded, psf), fresh(coded, other), rtol=0, atol=0)
        layer.wiener.theta.add_(1.5)
        torch.testing.assert_close(layer(coded, psf), fresh(coded, other), rtol=0, atol=0)
        small = coded[..., :16, :12]
        torch.testing.assert_close(layer(small, psf), fresh(small, other), rtol=0, atol=0)


def test_coded_features_train_through_lambda_after_an_inference_call():
    """A filter kept by an inference call must not stand in for the differentiable one: with autograd on, the
    loss reaches λ (and the PSF)."""
    from doefab.reconstruction.networks import CodedFeatures

    layer = CodedFeatures(2, 2, raw=False).double()
    psf = torch.stack([_gauss(5, 0.7), _gauss(5, 1.1)])[None].double()
    coded = torch.rand(1, 3, 16, 16, dtype=torch.float64)
    with torch.no_grad():
        layer(coded, psf)
    p = psf.clone().requires_grad_(True)
    layer(coded, p).square().sum().backward()
    assert layer.wiener.theta.grad is not None and float(layer.wiener.theta.grad.abs().min()) > 0
    assert p.grad is not None and float(p.grad.abs().max()) > 0


def test_deconvolution_is_the_wiener_formula_on_the_edge_replicated_canvas():
    """Against the formula written out here: the image edge-replicated by K // 2 + 1 pixels, its FFT times
    conj(K) / (|K|² + λ) with K the unit-sum PSF's OTF (centre pixel at the origin), inverse-transformed with numpy
    and cropped back; per channel λ, and every image with every PSF (``each``)."""
    rng = np.random.default_rng(4)
    y = torch.from_numpy(rng.random((2, 2, 13, 18)))
    psf = torch.from_numpy(rng.random((1, 3, 5, 5)))
    lam = torch.tensor([0.03, 0.1, 0.3, 0.05, 0.2, 0.01], dtype=torch.float64)
    got = wiener_deconvolve(y, psf, lam, each=True).numpy()
    pad = np.pad(y.numpy(), ((0, 0), (0, 0), (3, 3), (3, 3)), mode="edge")
    for c in range(3):
        p = psf[0, c].numpy() / psf[0, c].numpy().sum()
        canvas = np.zeros(pad.shape[-2:])
        canvas[:5, :5] = p
        otf = np.fft.fft2(np.roll(canvas, (-2, -2), axis=(0, 1)))
        for f in range(2):
            want = np.fft.ifft2(np.fft.fft2(pad[:, f]) * otf.conj() / (np.abs(otf) ** 2 + float(lam[c * 2 + f]))).real
            np.testing.assert_allclose(got[:, c * 2 + f], want[:, 3:16, 3:21], atol=1e-10)


def test_a_lambda_per_output_widens_a_single_channel_deconvolution():
    """One image and one PSF with three λ: three deconvolutions, each the one its λ alone gives."""
    rng = np.random.default_rng(6)
    y = torch.from_numpy(rng.random((1, 1, 12, 12)))
    psf = _gauss(5, 0.9).double()[None, None]
    lam = torch.tensor([0.01, 0.1, 1.0], dtype=torch.float64)
    got = wiener_deconvolve(y, psf, lam)
    want = torch.cat([wiener_deconvolve(y, psf, float(v)) for v in lam], dim=1)
    assert got.shape == (1, 3, 12, 12)
    torch.testing.assert_close(got, want, rtol=0, atol=1e-12)
