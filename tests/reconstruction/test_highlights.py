"""The least-squares radiance solve: against a dense least-squares solution built independently, and what the
streak recovers that the plain capture alone cannot."""

import numpy as np
import pytest
import torch
from scipy.signal import convolve2d

from doefab.errors import DoefabError
from doefab.reconstruction.highlights import highlight_support, solve_highlights

K = 9
M = K // 2


def _psfs(one_sided=False):
    """A plain half (compact, 0.5 of the light) and a streak half (a weak cross, 0.5 of the light; ``one_sided``:
    its right and lower arms only, a PSF whose OTF is not real)."""
    plain = np.zeros((K, K))
    plain[M, M], plain[M, M - 1], plain[M, M + 1], plain[M - 1, M], plain[M + 1, M] = 0.4, 0.025, 0.025, 0.025, 0.025
    streak = np.zeros((K, K))
    arm = slice(M, None) if one_sided else slice(None)
    streak[M, arm] = 0.005 * (2 if one_sided else 1)
    streak[arm, M] = 0.005 * (2 if one_sided else 1)
    streak[M, M] = 0.5 - 16 * 0.005
    return (torch.from_numpy(np.repeat(streak[None], 3, 0)).float(),
            torch.from_numpy(np.repeat(plain[None], 3, 0)).float())


def _render(scene, psf):
    """'same' convolution of a [3, H, W] scene on a canvas with M px of replicated border, cropped back."""
    out = []
    for c in range(3):
        big = np.pad(scene[c], M, mode="edge")
        out.append(convolve2d(big, psf[c].numpy(), mode="same")[M:-M, M:-M])
    return np.stack(out)


def _scene(size=32):
    rng = np.random.default_rng(4)
    s = 0.2 + 0.6 * rng.random((3, size, size))
    yy, xx = np.mgrid[:size, :size]
    blob = (yy - 15) ** 2 + (xx - 17) ** 2 <= 4
    s[:, blob] = (30.0 * 2.0 ** (-((yy - 15) ** 2 + (xx - 17) ** 2) / 4.0))[blob]  # a lamp, 5 stops of fall-off
    return s


def _captures(scene, one_sided=False):
    pc, pu = _psfs(one_sided)
    coded, uncoded = (np.clip(_render(scene, p), 0, 1) for p in (pc, pu))
    return pc, pu, coded, uncoded


def _dense_problems(scene, uncoded, coded, pc, pu):
    """Per channel, built independently of the solve: the start ``x0`` (frame and M-px margin, flattened), the
    matrix of the unclipped pixels of both captures (columns by convolving unit impulses), the residual at the
    start and the Jacobi scaling from the dense columns."""
    size = scene.shape[-1]
    big = size + 2 * M
    support = highlight_support(torch.from_numpy(uncoded)[None])[0, 0].numpy() > 0
    share = pu.double().sum(dim=(-2, -1)).numpy()
    out = []
    for c in range(3):
        x0 = np.pad(np.where(support, 1.0 / share[c], uncoded[c] / share[c]), M, mode="edge").ravel()
        cols, rhs = [], []
        for psf, y in ((pc, coded), (pu, uncoded)):
            keep = (y[c] < 0.98).ravel()
            a = np.empty((size * size, big * big))
            for j in range(big * big):
                e = np.zeros(big * big)
                e[j] = 1.0
                a[:, j] = convolve2d(e.reshape(big, big), psf[c].numpy(), mode="same")[M:-M, M:-M].ravel()
            cols.append(a[keep])
            rhs.append((y[c].ravel() - a @ x0)[keep])
        a, r = np.concatenate(cols), np.concatenate(rhs)
        norm = np.linalg.norm(a, axis=0)
        scale = np.where(norm ** 2 > 1e-6 * (norm ** 2).max(), 1.0 / np.maximum(norm, 1e-300), 0.0)
        out.append((x0, a * scale, r, scale))
    return out


def _frame(x, size):
    return np.clip(x, 0, 256).reshape(size + 2 * M, size + 2 * M)[M:-M, M:-M]


def test_cgls_converges_to_the_dense_least_squares_solution():
    scene = _scene()
    pc, pu, coded, uncoded = _captures(scene)
    c_t, u_t = (torch.from_numpy(x)[None] for x in (coded, uncoded))
    got = solve_highlights(c_t, u_t, pc.double(), pu.double(), iters=400, dtype=torch.float64)[0].numpy()
    # independent: numpy's minimum-norm least squares of the scaled dense problem from the same start
    for c, (x0, b, r, scale) in enumerate(_dense_problems(scene, uncoded, coded, pc, pu)):
        z = np.linalg.lstsq(b, r, rcond=None)[0]
        np.testing.assert_allclose(got[c], _frame(x0 + scale * z, scene.shape[-1]), rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("iters", [1, 2, 3])
def test_each_cgls_iterate_is_the_least_squares_minimiser_over_its_krylov_subspace(iters):
    # k steps of CG on the normal equations minimise the residual over the k-dimensional Krylov subspace
    # span{g, (BᵀB) g, …} with g = Bᵀr: built here by QR, without the recurrence; one step more or fewer differs.
    # The solve takes its steps for the three colours together: one block-diagonal system
    from scipy.linalg import block_diag

    scene = _scene(16)
    pc, pu, coded, uncoded = _captures(scene, one_sided=True)
    c_t, u_t = (torch.from_numpy(x)[None] for x in (coded, uncoded))
    got = solve_highlights(c_t, u_t, pc.double(), pu.double(), iters=iters, dtype=torch.float64)[0].numpy()
    x0, b, r, scale = (list(z) for z in zip(*_dense_problems(scene, uncoded, coded, pc, pu)))
    b, r = block_diag(*b), np.concatenate(r)
    basis = [b.T @ r]
    for _ in range(iters - 1):
        basis.append(b.T @ (b @ basis[-1]))
    v = np.linalg.qr(np.stack(basis, 1))[0]
    z = np.split(v @ np.linalg.lstsq(b @ v, r, rcond=None)[0], 3)
    for c in range(3):
        np.testing.assert_allclose(got[c], _frame(x0[c] + scale[c] * z[c], scene.shape[-1]), rtol=1e-9, atol=1e-9)


def test_the_streak_recovers_what_the_plain_capture_clips():
    scene = _scene()
    pc, pu, coded, uncoded = _captures(scene)
    c_t, u_t = (torch.from_numpy(x)[None].float() for x in (coded, uncoded))
    hl = scene.max(axis=0) > 2.0
    start = solve_highlights(c_t, u_t, pc, pu, iters=0)[0].numpy()  # the clipping level
    both = solve_highlights(c_t, u_t, pc, pu)[0].numpy()
    plain = solve_highlights(c_t, u_t, pc, pu, views=("uncoded",))[0].numpy()

    def err(x):
        return np.abs(x - scene)[:, hl].mean()

    assert err(both) < 0.1 * err(start)
    assert err(both) < 0.1 * err(plain)  # the plain capture alone sees its clipped interior only through glow
    assert err(both) < 0.1 * scene[:, hl].mean()


def test_start_and_fit_without_clipping():
    pc, pu = _psfs()
    scene = 0.5 + 0.4 * np.random.default_rng(1).random((3, 24, 24))
    coded, uncoded = (torch.from_numpy(_render(scene, p))[None].float() for p in (pc, pu))
    start = solve_highlights(coded, uncoded, pc, pu, iters=0)
    torch.testing.assert_close(start, uncoded / pu.sum(dim=(-2, -1)).view(1, 3, 1, 1))
    solved = solve_highlights(coded, uncoded, pc, pu, iters=20)
    frame = (slice(None), slice(None), slice(M, -M), slice(M, -M))  # away from the unknown margin
    e0 = (start - torch.from_numpy(scene)[None].float())[frame].abs().mean()
    e1 = (solved - torch.from_numpy(scene)[None].float())[frame].abs().mean()
    assert e1 < 0.5 * e0  # the solve also undoes the blur of the unclipped scene


def test_bad_inputs_are_refused():
    pc, pu = _psfs()
    with pytest.raises(DoefabError, match="captures"):
        solve_highlights(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 9), pc, pu)
    with pytest.raises(DoefabError, match="PSFs"):
        solve_highlights(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 8), pc, pu[:2])
    with pytest.raises(DoefabError, match="views"):
        solve_highlights(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 8), pc, pu, views=("plain",))
    with pytest.raises(DoefabError, match="bound_rounds"):
        solve_highlights(torch.rand(1, 3, 8, 8), torch.rand(1, 3, 8, 8), pc, pu, bound_iters=4, bound_rounds=0)


@pytest.mark.parametrize("variant,views", [("proposed", ("coded", "uncoded")), ("coded_only", ("coded",)),
                                           ("uncoded_only", ("uncoded",))])
def test_hdr_networks_start_from_the_solve_of_the_captures_they_see(variant, views):
    from doefab.reconstruction.hdrnet import HDRNet

    scene = np.pad(_scene(), ((0, 0), (16, 16), (16, 16)), mode="reflect")  # 64²
    pc, pu, coded, uncoded = _captures(scene)
    coded, uncoded = (torch.from_numpy(x)[None].float() for x in (coded, uncoded))
    net = HDRNet(variant, features=1, width=4, highlight_iters=20, bound_iters=8, bound_rounds=2).eval()
    with torch.no_grad():
        y = net(coded, uncoded, torch.cat([pc, pu])[None])
    expect = solve_highlights(coded, uncoded, pc, pu, iters=20, views=views, bound_iters=8, bound_rounds=2)
    torch.testing.assert_close(y, expect, rtol=1e-4, atol=1e-4)  # zero-initialised head: exactly the solve
    with pytest.raises(DoefabError, match=r"psf must be \[B, 6"):
        net(coded, uncoded, pc[None])
    with pytest.raises(DoefabError, match="least-squares solve"):
        HDRNet(variant, highlight_iters=0)


def _bright_disc(size=32, radiance=60.0, radius=3.0):
    s = 0.2 + 0.6 * np.random.default_rng(7).random((3, size, size))
    yy, xx = np.mgrid[:size, :size]
    s[:, (yy - 16) ** 2 + (xx - 15) ** 2 <= radius ** 2] = radiance
    return s


def test_the_bounded_stage_keeps_clipped_coded_pixels_at_full_well():
    # a disc bright enough that the streak clips along its arms: least squares alone leaves clipped coded
    # pixels predicted below full well; the bounded stage lifts them (re-rendered independently here)
    scene = _bright_disc()
    pc, pu, coded, uncoded = _captures(scene)
    c_t, u_t = (torch.from_numpy(x)[None].float() for x in (coded, uncoded))
    over = coded >= 0.98
    plain = solve_highlights(c_t, u_t, pc, pu, iters=40)[0].numpy()
    bounded = solve_highlights(c_t, u_t, pc, pu, iters=40, bound_iters=40, bound_rounds=8)[0].numpy()

    def shortfall(x):  # how far clipped coded pixels fall below full well, rendered from the estimate
        return np.clip(0.98 - _render(x.astype(np.float64), pc)[over], 0, None).mean()

    inner = (slice(None), slice(M, -M), slice(M, -M))  # pixels the unknown margin does not reach
    assert over[inner].any()
    assert shortfall(bounded) < 0.2 * shortfall(plain)
    hl = scene.max(axis=0) > 2.0
    assert np.abs(bounded - scene)[:, hl].mean() < np.abs(plain - scene)[:, hl].mean()


def test_float32_solve_matches_float64_wherever_a_capture_measures_the_pixel():
    """Numerical limit: where both captures clip, the data bound the radiance from below only and the bounded
    stage's result there may follow rounding; everywhere else float32 must reach the float64 solution."""
    scene = _scene()
    yy, xx = np.mgrid[:32, :32]
    core = (yy - 15) ** 2 + (xx - 17) ** 2 <= 9
    scene[:, core] = 200.0  # a lamp bright enough to clip the streak's core too
    pc, pu, coded, uncoded = _captures(scene)
    c_t, u_t = (torch.from_numpy(x)[None].float() for x in (coded, uncoded))
    both = (coded >= 0.98).any(0) & (uncoded >= 0.98).any(0)
    assert both.sum() >= 9  # the case under test: pixels no capture measures
    got = {dt: solve_highlights(c_t, u_t, pc, pu, iters=40, dtype=dt, bound_iters=40, bound_rounds=8)[0].double()
           for dt in (torch.float32, torch.float64)}
    diff = (got[torch.float32] - got[torch.float64]).abs().amax(0).numpy()
    assert diff[~both].max() <= 1e-2  # radiance (the solve's range is 0–256)
