"""Illuminant search: the smooth inverses are exact for smooth reflectances, the search finds the illuminant
from a dispersed capture, and the proposed hyperspectral network starts from the inverse it picks."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from doefab.errors import DoefabError
from doefab.imaging.sensor import sensor_response
from doefab.reconstruction.data import HS_WAVELENGTHS_M
from doefab.reconstruction.illuminant import illuminant_inverses, illuminant_library, search_illuminant

T = sensor_response(HS_WAVELENGTHS_M).astype(np.float64)
LAM = np.arange(31)


def _library():
    flat = np.ones(31)
    spiky_blue = 0.2 + np.exp(-0.5 * ((LAM - 6) / 0.8) ** 2)
    spiky_red = 0.2 + np.exp(-0.5 * ((LAM - 22) / 0.8) ** 2)
    return np.stack([flat, spiky_blue, spiky_red])


def test_inverse_solves_its_regularised_least_squares_and_reproduces_the_capture():
    lib = _library()
    inv = illuminant_inverses(T, lib, smooth=1e-3, eps=1e-6)
    assert inv.shape == (3, 31, 3)
    rho = 0.2 + 0.6 * LAM / 30
    d2 = np.diff(np.eye(31), 2, axis=0)
    for j, e in enumerate(lib):
        c = 0.5 * T @ (e * rho)
        # independent: the stacked least-squares system [A; √μ D²; √ε I] ρ = [c; 0; 0], solved by lstsq
        a = 0.5 * T * e[None, :]
        big = np.vstack([a, np.sqrt(1e-3) * d2, np.sqrt(1e-6) * np.eye(31)])
        rho_ls = np.linalg.lstsq(big, np.concatenate([c, np.zeros(29 + 31)]), rcond=None)[0]
        np.testing.assert_allclose(inv[j] @ c, e * rho_ls, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(0.5 * T @ (inv[j] @ c), c, rtol=3e-2)  # reproduces the capture (regularised)


def _dispersed_scene(e, size=64, seed=0):
    """Half-exposure captures of regions with linear-in-wavelength reflectances under ``e``; the coded PSF of
    band l is a delta shifted by l // 3 − 5 pixels (a synthetic grating)."""
    rng = np.random.default_rng(seed)
    regions = (np.add.outer(np.arange(size) // 9, np.arange(size) // 13) % 4)
    a, b = rng.uniform(0.1, 0.5, 4), rng.uniform(-0.3, 0.3, 4)
    rho = np.clip(a[regions][None] + b[regions][None] * (LAM[:, None, None] / 30), 0.02, 1)
    s = torch.from_numpy(e[:, None, None] * rho)
    k = 15
    psf = torch.zeros(31, k, k, dtype=torch.float64)
    for band in range(31):
        psf[band, k // 2, k // 2 + band // 3 - 5] = 0.5
    pad = k // 2
    sp = F.pad(s[None], (pad, pad, pad, pad), mode="replicate")[0]
    bands = torch.stack([F.conv2d(sp[i][None, None], psf[i].flip(-1, -2)[None, None])[0, 0] for i in range(31)])
    tt = torch.from_numpy(T)
    coded = torch.einsum("rl,lhw->rhw", tt, bands)
    uncoded = 0.5 * torch.einsum("rl,lhw->rhw", tt, s)
    return coded[None], uncoded[None], psf


@pytest.mark.parametrize("true_j", [0, 1, 2])
def test_search_finds_the_illuminant_rgb_cannot_tell(true_j):
    lib = _library()
    inv = torch.from_numpy(illuminant_inverses(T, lib))
    coded, uncoded, psf = _dispersed_scene(lib[true_j])
    idx, cost = search_illuminant(coded, uncoded, psf, torch.from_numpy(T), inv)
    assert int(idx[0]) == true_j
    others = torch.cat([cost[0, :true_j], cost[0, true_j + 1:]])
    assert float(cost[0, true_j]) < 0.1 * float(others.min())  # the smooth inverse is not exact: not 0


def test_shipped_library_is_colour_sciences_illuminants_at_peak_one():
    from doefab.reconstruction.data import illuminant_spectra
    from doefab.reconstruction.illuminant import LIBRARY_PATH, _read_library

    names, lib = _read_library(str(LIBRARY_PATH))
    assert lib.shape == (len(names), 31) and len(names) >= 20
    np.testing.assert_allclose(lib.max(axis=1), 1.0)
    installed = dict(zip(*illuminant_spectra()))
    common = [n for n in names if n in installed]
    assert len(common) >= 0.9 * len(names)  # the installed colour-science still has (almost) all of them
    for n in common:  # ... with the same spectra (the file stores 10 significant digits)
        np.testing.assert_allclose(lib[names.index(n)], installed[n], rtol=1e-8, atol=1e-10)


def test_library_round_trip_and_corrupt_file(tmp_path):
    from doefab.reconstruction.illuminant import write_illuminant_library

    path = write_illuminant_library(tmp_path / "lib.csv")
    np.testing.assert_allclose(illuminant_library(path), illuminant_library(), rtol=1e-8, atol=1e-10)
    bad = tmp_path / "bad.csv"
    bad.write_text(path.read_text().replace(",", ";", 40))
    with pytest.raises(DoefabError, match="illuminant library"):
        illuminant_library(bad)


def test_bad_shapes_are_refused():
    with pytest.raises(DoefabError, match="response"):
        illuminant_inverses(T[:2], _library())
    with pytest.raises(DoefabError, match="inverses"):
        search_illuminant(torch.rand(1, 3, 64, 64), torch.rand(1, 3, 64, 64), torch.rand(31, 5, 5),
                          torch.rand(3, 31), torch.rand(2, 30, 3))


def test_proposed_network_starts_from_the_inverse_it_picks():
    from doefab.reconstruction.spectralnet import SpectralNet

    lib = _library()
    inv = illuminant_inverses(T, lib)
    net = SpectralNet(31, "proposed", features=1, width=4, baseline=np.zeros((31, 3)), illuminant=(T, inv)).eval()
    coded, uncoded, psf = _dispersed_scene(lib[1])
    with torch.no_grad():
        y = net(coded.float(), uncoded.float(), psf[None].float())
    expect = torch.einsum("oc,bchw->bohw", torch.from_numpy(inv[1]).float(), uncoded.float()).clamp_min(0)
    assert torch.allclose(y, expect, atol=1e-5)  # zero-initialised residual head: exactly the picked inverse


def test_large_captures_are_searched_on_their_centre():
    lib = _library()
    inv = torch.from_numpy(illuminant_inverses(T, lib))
    coded, uncoded, psf = _dispersed_scene(lib[2], size=96)
    t = torch.from_numpy(T)
    _, cost_big = search_illuminant(coded, uncoded, psf, t, inv, max_side=64)
    _, cost_crop = search_illuminant(coded[..., 16:80, 16:80], uncoded[..., 16:80, 16:80], psf, t, inv)
    assert torch.allclose(cost_big, cost_crop)


@pytest.mark.parametrize("true_j", [1, 2])
def test_the_mixture_puts_a_library_light_on_its_own_member(true_j):
    from doefab.reconstruction.illuminant import mix_illuminants

    lib = _library()
    inv = torch.from_numpy(illuminant_inverses(T, lib))
    coded, uncoded, psf = _dispersed_scene(lib[true_j])
    w = mix_illuminants(coded, uncoded, psf, torch.from_numpy(T), inv)[0].numpy()
    assert w.argmax() == true_j and w[true_j] > 0.8 * w.sum() and np.all(w >= 0)


def test_light_between_two_members_is_met_by_their_blend_not_by_one_of_them():
    """A lamp that is half the blue and half the red spike (no library member): the fitted mixture weighs both
    and its spectra are closer to the truth than those of the best single member."""
    from doefab.reconstruction.illuminant import mix_illuminants

    lib = _library()
    inv = torch.from_numpy(illuminant_inverses(T, lib))
    light = 0.5 * (lib[1] + lib[2])
    coded, uncoded, psf = _dispersed_scene(light, seed=3)
    tt = torch.from_numpy(T)
    w = mix_illuminants(coded, uncoded, psf, tt, inv)[0].double()
    assert w[1] > 0.2 * w.sum() and w[2] > 0.2 * w.sum()
    idx, _ = search_illuminant(coded, uncoded, psf, tt, inv)
    # the truth: the spectra the scene was made of, recovered from the captures' construction
    rng = np.random.default_rng(3)
    regions = (np.add.outer(np.arange(64) // 9, np.arange(64) // 13) % 4)
    a, b = rng.uniform(0.1, 0.5, 4), rng.uniform(-0.3, 0.3, 4)
    truth = light[:, None, None] * np.clip(a[regions][None] + b[regions][None] * (LAM[:, None, None] / 30), 0.02, 1)
    mixed = torch.einsum("j,joc,chw->ohw", w / w.sum(), inv, uncoded[0]).numpy()
    single = torch.einsum("oc,chw->ohw", inv[int(idx[0])], uncoded[0]).numpy()
    assert np.abs(mixed - truth).mean() < 0.7 * np.abs(single - truth).mean()


@pytest.mark.parametrize("kind", ["black", "clipped", "nan"])
def test_a_capture_that_says_nothing_falls_back_to_one_member(kind):
    """A black or wholly clipped coded capture has no unclipped pixel to fit, and one with a NaN pixel nothing a
    least-squares fit can use: the mixture falls back to a single member (weights sum to one), never to an error
    or to all-zero weights."""
    from doefab.reconstruction.illuminant import mix_illuminants

    lib = _library()
    inv = torch.from_numpy(illuminant_inverses(T, lib))
    coded, uncoded, psf = _dispersed_scene(lib[1])
    if kind == "nan":  # a NaN pixel (a dead pixel's value) reaches every prediction through the convolution
        uncoded = uncoded.clone()
        uncoded[..., 5, 7] = float("nan")
    else:
        coded = torch.zeros_like(coded) if kind == "black" else torch.ones_like(coded)
    w = mix_illuminants(coded, uncoded, psf, torch.from_numpy(T), inv)[0]
    assert float(w.sum()) == pytest.approx(1.0) and int((w > 0).sum()) == 1


def test_the_mixture_is_well_posed_for_the_shipped_library():
    """The shipped library's 50-odd members are nearly collinear as predictors; the weights must still be the
    non-negative least-squares solution (checked with scipy's nnls on the full system)."""
    from scipy.optimize import nnls

    from doefab.reconstruction.illuminant import candidate_predictions, mix_illuminants

    lib = illuminant_library()
    inv = torch.from_numpy(illuminant_inverses(T, lib))
    coded, uncoded, psf = _dispersed_scene(0.5 * (lib[3] + lib[20]), size=32, seed=2)
    w = mix_illuminants(coded, uncoded, psf, torch.from_numpy(T), inv)[0].double().numpy()
    pred, target, valid = candidate_predictions(coded, uncoded, psf, torch.from_numpy(T), inv)
    a = (pred[0] * valid[0][None]).reshape(len(lib), -1).double().numpy()
    b = (target[0] * valid[0]).reshape(-1).double().numpy()
    ref, _ = nnls(a.T, b)
    assert np.linalg.norm(a.T @ w - b) <= np.linalg.norm(a.T @ ref - b) * (1 + 1e-4) + 1e-9


@pytest.mark.parametrize("k", [5, 6])
def test_candidate_predictions_follow_their_definition_for_odd_and_even_psfs(k):
    """pred[j, r] = Σ_{λ,c} T[r,λ] N_j[λ,c] (p_λ ∗ u_c), each band's PSF centred on its pixel k // 2 and the frame's
    edges replicated — computed here pixel by pixel."""
    from doefab.reconstruction.illuminant import candidate_predictions

    rng = np.random.default_rng(3)
    n_bands, n_cand, h, w = 2, 3, 11, 9
    uncoded = rng.random((1, 3, h, w))
    coded = rng.random((1, 3, h, w))
    psf = rng.random((n_bands, k, k))
    resp = rng.random((3, n_bands))
    inv = rng.random((n_cand, n_bands, 3))
    pred, target, _ = candidate_predictions(*(torch.from_numpy(a) for a in (coded, uncoded, psf, resp, inv)))
    ys, xs = np.arange(h)[:, None], np.arange(w)[None, :]
    conv = np.zeros((n_bands, 3, h, w))
    for lam in range(n_bands):
        for i in range(k):
            for j in range(k):
                rows = np.clip(ys + k // 2 - i, 0, h - 1)
                cols = np.clip(xs + k // 2 - j, 0, w - 1)
                conv[lam] += psf[lam, i, j] * uncoded[0][:, rows, cols]
    want = np.einsum("rl,jlc,lchw->jrhw", resp, inv, conv).reshape(n_cand, 3, h * w)
    np.testing.assert_allclose(pred[0].numpy(), want, rtol=1e-5, atol=1e-5 * np.abs(want).max())
    np.testing.assert_allclose(target[0].numpy(), coded[0].reshape(3, -1), rtol=1e-6)
