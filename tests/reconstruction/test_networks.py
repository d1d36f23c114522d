import numpy as np
import pytest
import torch

from doefab.errors import DoefabError
from doefab.reconstruction.hdrnet import HDRNet
from doefab.reconstruction.depthnet import DepthNet, depth_loss
from doefab.reconstruction.spectralnet import SpectralNet
from doefab.reconstruction.resnet import ResNet18Trunk


def _psf(b, n, k=15):
    p = torch.rand(b, n, k, k)
    return 0.5 * p / p.sum(dim=(-2, -1), keepdim=True)


def test_resnet18_trunk_structure():
    t = ResNet18Trunk(3, 8)
    blocks = sum(len(s) for s in t.stages)
    assert blocks == 8  # [2, 2, 2, 2] BasicBlocks
    feats = t(torch.rand(1, 3, 64, 96))
    assert [f.shape[-1] for f in feats] == [48, 24, 12, 6, 3]
    assert [f.shape[1] for f in feats] == [8, 8, 16, 32, 64]


def _spectral(variant, width=4):
    return SpectralNet(31, variant, features=2, width=width, baseline=np.full((31, 3), 0.1))


def _hdr(variant, width=4):
    return HDRNet(variant, features=2, width=width, highlight_iters=2, bound_iters=2, bound_rounds=1)


@pytest.mark.parametrize("variant", ["proposed", "coded_only", "uncoded_only"])
@pytest.mark.parametrize("task", ["hdr", "hyperspectral"])
def test_networks_shapes_and_gradients(variant, task):
    net, out, n_psf = (_hdr(variant), 3, 6) if task == "hdr" else (_spectral(variant), 31, 31)
    coded, uncoded = torch.rand(2, 3, 64, 96) * 0.5, torch.rand(2, 3, 64, 96) * 0.5
    y = net(coded, uncoded, _psf(1, n_psf))
    assert y.shape == (2, out, 64, 96)
    y.mean().backward()
    # the residual heads start at zero: every parameter still gets a gradient through the head's weights
    assert all(p.grad is not None for p in net.parameters() if p.requires_grad)


def test_outputs_are_non_negative_at_inference():
    net = _hdr("proposed").eval()
    with torch.no_grad():
        assert bool((net(torch.rand(1, 3, 64, 64) * 0.5, torch.rand(1, 3, 64, 64) * 0.5, _psf(1, 6)) >= 0).all())


@pytest.mark.parametrize("variant", ["proposed", "coded_only", "uncoded_only"])
def test_depth_net_shapes_and_gradients(variant):
    net = DepthNet(variant, width=4)
    y = net(torch.rand(2, 3, 64, 64), torch.rand(2, 3, 64, 64))
    assert y.shape == (2, 64, 64) and bool((y > 0).all())
    depth_loss(y, torch.full_like(y, 3.0)).backward()
    assert all(p.grad is not None for p in net.parameters())


def test_depth_net_with_cost_volume_uses_the_psfs():
    torch.manual_seed(0)
    net = DepthNet("proposed", width=4, cost_volume=True, planes=3)
    psf = torch.rand(2, 3, 3, 9, 9)
    psf = psf / psf.sum(dim=(-2, -1), keepdim=True)
    coded, uncoded = torch.rand(2, 3, 64, 64), torch.rand(2, 3, 64, 64)
    y = net(coded, uncoded, psf)
    assert y.shape == (2, 64, 64)
    depth_loss(y, torch.full_like(y, 3.0)).backward()
    assert all(p.grad is not None for p in net.parameters())
    with torch.no_grad():  # the output depends on the PSFs it is given (the cost volume is an input)
        assert not torch.allclose(net(coded, uncoded, psf), net(coded, uncoded, psf.flip(1)))
    with pytest.raises(DoefabError, match="needs psf"):
        net(coded, uncoded)
    with pytest.raises(DoefabError, match="both captures"):
        DepthNet("coded_only", width=4, cost_volume=True)


def test_a_few_training_steps_lower_the_loss():
    torch.manual_seed(0)
    net = _spectral("proposed", width=8)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    coded, uncoded = torch.rand(2, 3, 64, 64), torch.rand(2, 3, 64, 64)
    psf = _psf(1, 31)
    losses = []
    for _ in range(60):
        opt.zero_grad()
        loss = (net(coded, uncoded, psf) - uncoded.mean(1, keepdim=True)).abs().mean()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert min(losses[-5:]) < 0.85 * losses[0]


def test_depth_loss_is_eq28():
    t = torch.zeros(1, 4, 4)
    p = torch.zeros(1, 4, 4)
    p[0, :, 2:] = 1.0  # a step: L1 = 0.5, horizontal gradient term 4/12, vertical 0
    assert float(depth_loss(p, t)) == pytest.approx(0.5 + 4 / 12)


@pytest.mark.parametrize("shape", [(1, 3, 60, 64), (1, 3, 32, 32), (1, 1, 64, 64)])
def test_bad_input_sizes_are_refused(shape):
    net = _spectral("uncoded_only")
    with pytest.raises(DoefabError, match="multiples of 32|\\[B, 3, H, W\\]"):
        net(torch.rand(*shape), torch.rand(*shape), _psf(1, 31))


def test_hdr_loss_is_the_l1_of_log_radiance():
    """Eq. 20's log term, computed independently in float64; a highlight's error counts through its log only."""
    from doefab.reconstruction.models import loss_fn

    target = torch.full((1, 3, 4, 4), 0.5)
    target[0, :, 1, 1] = torch.tensor([100.0, 50.0, 1.0])  # one highlight pixel
    assert float(loss_fn("hdr", target.clone(), target)) == 0.0
    pred = target.clone()
    pred[0, 0, 1, 1] = 80.0   # −20 in the highlight's red channel
    pred[0, 2, 3, 3] = 0.25   # a dark pixel off by half
    t, p = target.numpy().astype(np.float64), pred.numpy().astype(np.float64)
    want = (abs(np.log(81.0) - np.log(101.0)) + abs(np.log(1.25) - np.log(1.5))) / t.size
    assert abs(float(loss_fn("hdr", pred, target)) - want) < 1e-6
    assert abs(want - np.abs(np.log1p(p) - np.log1p(t)).mean()) < 1e-12


def test_the_coded_only_spectral_baseline_reads_each_band_where_its_light_landed():
    """A grating moves band λ to its first order; the coded-only ablation's estimate of band λ must read the
    capture there (independent check: a band's PSF is a single off-centre pixel, the capture a bright dot)."""
    k, n = 31, 5
    psf = torch.zeros(1, n, k, k)
    offs = [(0, 3), (0, 5), (1, 7), (0, 9), (-2, 11)]
    for lam, (dy, dx) in enumerate(offs):
        psf[0, lam, k // 2 + dy, k // 2 + dx] = 0.5
    net = SpectralNet(n, "coded_only", features=1, width=4, baseline=torch.eye(n, 3) + 0.0).eval()
    coded = torch.zeros(1, 3, 64, 64)
    coded[0, 0, 30 + offs[0][0], 20 + offs[0][1]] = 1.0  # band 0's light from the scene point (30, 20)
    coded[0, 1, 30 + offs[1][0], 20 + offs[1][1]] = 1.0
    with torch.no_grad():
        base = net._baseline(coded, None, psf)
    assert float(base[0, 0, 30, 20]) == 1.0 and float(base[0, 1, 30, 20]) == 1.0  # registered back to (30, 20)
    assert float(base[0, 0].sum()) == 1.0


def test_the_proposed_spectral_network_starts_at_the_mixture_of_illuminant_estimates():
    """With ``illuminant_mix`` the untrained proposed network (zero residual head) returns exactly the blend of the
    library's estimates the mixture fit weighs (normalised weights), computed here from ``mix_illuminants``."""
    from doefab.reconstruction.illuminant import mix_illuminants
    from doefab.reconstruction.models import build_model, default_arch

    arch = default_arch("hyperspectral", "proposed")
    assert arch["illuminant_mix"] is True
    net = build_model("hyperspectral", "proposed", arch).eval()
    torch.manual_seed(0)
    coded, uncoded = 0.5 * torch.rand(1, 3, 64, 64), 0.5 * torch.rand(1, 3, 64, 64)
    psf = _psf(1, 31)
    with torch.no_grad():
        out = net(coded, uncoded, psf)
        w = mix_illuminants(coded, uncoded, psf[0], net.response, net.inverses)[0]
        want = torch.einsum("j,joc,chw->ohw", w / w.sum(), net.inverses, uncoded[0]).clamp_min(0)
    assert torch.allclose(out[0], want, atol=1e-5)
    old = build_model("hyperspectral", "proposed", {**arch, "illuminant_mix": False}).eval()
    assert not old.mix  # a record written before the mixture keeps the single best member


def test_each_application_names_a_network_module_that_builds_its_networks():
    """Every application's ``network`` module builds the three variants from its default record (each seeing
    the captures ``VIEWS`` gives it) and has a loss; ``build_model`` is that module's ``build``."""
    import importlib

    from doefab.applications import APPLICATIONS
    from doefab.reconstruction.models import build_model, default_arch
    from doefab.reconstruction.networks import VIEWS

    for name, app in APPLICATIONS.items():
        mod = importlib.import_module(app.network)
        assert callable(mod.loss)
        for variant, views in VIEWS.items():
            net = mod.build(variant, mod.default_arch(variant))
            assert net.views == views and type(build_model(name, variant)) is type(net)
            assert default_arch(name, variant) == mod.default_arch(variant)


def test_no_network_switches_on_its_variant_inside_forward():
    """The variant is chosen when a network is built (its branches and estimate): no method a call runs reads
    ``self.variant`` (the planted method is found)."""
    import ast
    import inspect
    import textwrap

    from doefab.reconstruction.depthnet import DepthNet
    from doefab.reconstruction.hdrnet import HDRNet
    from doefab.reconstruction.spectralnet import SpectralNet

    def reads_variant(src: str) -> bool:
        return any(isinstance(n, ast.Attribute) and n.attr == "variant" and isinstance(n.value, ast.Name)
                   and n.value.id == "self" for n in ast.walk(ast.parse(src)))

    assert reads_variant("class A:\n    def forward(self):\n        return self.variant == 'x'\n")
    for cls in (DepthNet, HDRNet, SpectralNet):
        for name, fn in inspect.getmembers(cls, inspect.isfunction):
            if name != "__init__" and fn.__qualname__.startswith(cls.__name__):
                assert not reads_variant(textwrap.dedent(inspect.getsource(fn))), f"{cls.__name__}.{name}"
