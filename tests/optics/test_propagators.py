"""The routes agree where each is valid, and each refuses (with the fix named) where it is not."""

import math

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError, SamplingError
from doefab.optics.propagators.base import FocalSetup


def _rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.linalg.norm(a - b) / np.linalg.norm(b)


@pytest.fixture(scope="module")
def random_doe(small_camera):
    rng = np.random.default_rng(0)
    levels = rng.integers(0, 16, size=(small_camera.doe_pixels,) * 2)
    return doefab.levels_to_height(levels, small_camera)


@pytest.mark.parametrize("depth", ["focus", 0.5, math.inf])
def test_spectral_mft_fft_agree(small_camera, random_doe, depth):
    cam = small_camera
    z = cam.focus_distance if depth == "focus" else depth
    kw = dict(kernel_size=41, precision="float64", halves=("coded", "uncoded"))
    lams = [450e-9, 650e-9]
    spectral = doefab.split_aperture_psf(random_doe, cam, lams, [z], route="spectral", **kw)
    mft = doefab.split_aperture_psf(random_doe, cam, lams, [z], route="mft", pixel_nodes=8, **kw)
    fft = doefab.split_aperture_psf(random_doe, cam, lams, [z], route="fft", oversample=16, **kw)
    for half in ("coded", "uncoded"):
        # the spectral route applies the flat-pixel envelope at pixel centres (a < 1e-4 approximation)
        assert _rel(spectral[half], mft[half]) < 2e-4
        assert _rel(fft[half], spectral[half]) < 2e-3


@pytest.mark.parametrize("depth", [0.5, math.inf])
def test_spectral_pixel_integral_is_exact(small_camera, depth):
    """Without a DOE there is no envelope: the spectral route's pixel integral equals high-order quadrature."""
    kw = dict(kernel_size=41, precision="float64", halves=("coded", "full"))
    spectral = doefab.split_aperture_psf(None, small_camera, [450e-9], [depth], route="spectral", **kw)
    mft = doefab.split_aperture_psf(None, small_camera, [450e-9], [depth], route="mft", pixel_nodes=10, **kw)
    for half in ("coded", "full"):
        assert _rel(spectral[half], mft[half]) < 1e-8


def test_asm_route_agrees_where_it_is_valid():
    # a fine-pitched, small-aperture camera whose lens sphere the pupil grid resolves
    cam = doefab.Camera(aperture_diameter=0.2e-3, doe_pitch=1e-6, doe_pixels=200, sensor_pitch=1e-6,
                        sensor_distance=5e-3, focus_distance=1.0)
    kw = dict(kernel_size=81, precision="float64", halves=("coded", "uncoded"))
    h = doefab.blazed_grating_height(cam, 100, n_levels=8)  # first order 27 px off axis, inside the window
    asm = doefab.split_aperture_psf(h, cam, [550e-9], [cam.focus_distance], route="asm", **kw)
    spectral = doefab.split_aperture_psf(h, cam, [550e-9], [cam.focus_distance], route="spectral", **kw)
    for half in ("coded", "uncoded"):
        assert _rel(asm[half], spectral[half]) < 2e-2


def test_near_point_source_refused_with_fix():
    cam = doefab.Camera()
    with pytest.raises(SamplingError, match=r"pupil phase sampling.*pupil_oversample ≥"):
        doefab.split_aperture_psf(None, cam, [550e-9], [0.05], kernel_size=63)
    # the fix it names works: the same point with a finer pupil sampling is accepted
    doefab.PSFPlan(doefab.Camera(aperture_diameter=1.08e-3, doe_pixels=200), [550e-9], [0.05], 203,
                   pupil_oversample=4)  # a window that holds the plain half's 99 px blur (test_window_check.py)


@pytest.mark.parametrize("route", ["spectral", "mft", "fft"])
def test_coarse_pitch_and_huge_kernel_refused(route):
    coarse = doefab.Camera(doe_pitch=20e-6, doe_pixels=440)
    with pytest.raises(SamplingError, match="output window aliasing"):
        doefab.PSFPlan(coarse, [450e-9], [math.inf], 255, route=route)
    with pytest.raises(SamplingError, match=r"smaller kernel"):
        doefab.PSFPlan(doefab.Camera(), [400e-9], [math.inf], 1024, route=route)


def test_asm_refuses_default_camera():
    with pytest.raises(SamplingError, match=r"\[asm\] pupil phase sampling: the lens's converging wave"):
        doefab.PSFPlan(doefab.Camera(), [550e-9], [math.inf], 63, route="asm")


def test_fft_refuses_oversized_padding():
    with pytest.raises(SamplingError, match=r"\[fft\] padding"):
        doefab.PSFPlan(doefab.Camera(), [700e-9], [math.inf], 63, route="fft", oversample=64)


@pytest.mark.parametrize("form", ["complex tensor", "real tensor", "real array"])
def test_angular_spectrum_gaussian_beam(form):
    """Band-limited ASM against the analytic Gaussian beam (waist 40 µm, 4 mm, 633 nm); a real amplitude, as a
    tensor or an array, propagates as the complex field it is."""
    lam, w0, z, b, n = 633e-9, 40e-6, 4e-3, 1e-6, 512
    c = (np.arange(n) - n / 2) * b
    xx, yy = np.meshgrid(c, c)
    r2 = xx**2 + yy**2
    amplitude = np.exp(-r2 / w0**2)
    given = {"complex tensor": torch.from_numpy(amplitude.astype(np.complex128)),
             "real tensor": torch.from_numpy(amplitude), "real array": amplitude}[form]
    field = torch.from_numpy(amplitude.astype(np.complex128))
    out = doefab.angular_spectrum(given, b, lam, z).numpy()
    k = 2 * math.pi / lam
    zr = math.pi * w0**2 / lam
    q = z - 1j * zr  # complex beam parameter at the waist is -i z_R
    analytic = (-1j * zr / q) * np.exp(1j * k * r2 / (2 * q)) * np.exp(1j * k * z)  # e^{ikz} convention
    # the ASM is exact; the analytic beam is the paraxial solution (difference ~ (λ/πw0)² ≈ 3e-5)
    assert np.abs(out - analytic).max() < 2e-3
    assert np.sum(np.abs(out) ** 2) == pytest.approx(np.sum(np.abs(field.numpy()) ** 2), rel=1e-6)


def test_angular_spectrum_refuses_long_distance_and_a_field_that_is_not_one():
    with pytest.raises(DoefabError, match=r"field must be a \(\.\.\., Ny, Nx\) complex or real array"):
        doefab.angular_spectrum(torch.ones(128), 1e-6, 500e-9, 1e-3)
    field = torch.ones(128, 128, dtype=torch.complex128)
    with pytest.raises(SamplingError, match="transfer-function aliasing"):
        doefab.angular_spectrum(field * torch.exp(1j * torch.linspace(0, 300, 128))[None, :], 1e-6, 500e-9, 0.5)


@pytest.mark.parametrize("n, plane, budget", [(65, 5_248_000, 2**25), (5, 10, 2**25), (7, 100, 200), (3, 10**9, 2**25)])
def test_plane_batches_cover_every_plane_once_within_the_budget(monkeypatch, n, plane, budget):
    from doefab.optics.propagators import base

    monkeypatch.setattr(base, "BATCH_ELEMENTS", budget)
    runs = base.plane_batches(n, plane)
    assert [i for s in runs for i in range(s.start, s.stop)] == list(range(n))
    assert all(s.stop - s.start >= 1 for s in runs)
    assert all((s.stop - s.start) * plane <= budget for s in runs if s.stop - s.start > 1)


def test_spectral_batches_of_planes_equal_each_plane_alone(small_camera, random_doe, monkeypatch):
    """Depth planes transformed a few at a time give each plane's PSF as computed alone."""
    from doefab.optics.propagators import base

    zs = [0.4, 0.7, 1.5, 5.0, math.inf]
    kw = dict(kernel_size=41, halves=("coded",))
    alone = np.concatenate([doefab.split_aperture_psf(random_doe, small_camera, [450e-9, 650e-9], [z], **kw)["coded"]
                            for z in zs])
    monkeypatch.setattr(base, "BATCH_ELEMENTS", 1)  # one plane per transform
    one = doefab.split_aperture_psf(random_doe, small_camera, [450e-9, 650e-9], zs, **kw)["coded"]
    monkeypatch.setattr(base, "BATCH_ELEMENTS", 2**40)  # every plane in one transform
    every = doefab.split_aperture_psf(random_doe, small_camera, [450e-9, 650e-9], zs, **kw)["coded"]
    for got in (one, every):
        assert np.asarray(got).shape == alone.shape
        assert np.abs(np.asarray(got) - alone).max() <= 1e-6 * alone.max()
    assert np.abs(alone[0] - alone[-1]).max() > 1e-2 * alone.max()


@pytest.mark.parametrize("big", [16, 15])
@pytest.mark.parametrize("reverse", [False, True])
def test_pixel_matrix_integrates_the_intensity_over_each_pixel(reverse, big):
    """W · |FFT(p)|² equals the intensity |Σ_n p_n e^{−2πi n b u/(λs)}|² of a 1-D pupil integrated over each sensor
    pixel by 64-node Gauss–Legendre quadrature (a trigonometric polynomial: the quadrature is exact to rounding),
    for an even and an odd FFT length; with ``reverse`` the matrix reads the FFT at −j, which is the flipped
    pupil's intensity."""
    from doefab.optics.propagators.spectral import band_limited_pixel_matrix

    rng = np.random.default_rng(11)
    # pixels 0.2 mm wide: a third of the intensity's shortest period (λs/(5b) = 0.55 mm), so the pixel's sinc matters
    n, b, lam, s, pix = 6, 10e-6, 550e-9, 0.05, 2e-4
    p = rng.normal(size=n) + 1j * rng.normal(size=n)
    centres = (np.arange(9) - 4) * pix + 0.37 * pix
    w = band_limited_pixel_matrix(centres, n, big, b, lam, s, pix, reverse=reverse)
    got = w @ (np.abs(np.fft.fft(p, big)) ** 2)
    q = p[::-1] if reverse else p
    nodes, weights = np.polynomial.legendre.leggauss(64)
    want = []
    for c in centres:
        u = c + nodes * pix / 2
        field = np.exp(-2j * np.pi * np.outer(u, np.arange(n)) * b / (lam * s)) @ q
        want.append(np.sum(weights * np.abs(field) ** 2) * pix / 2)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12 * max(want))


def test_pixel_matrix_refuses_an_fft_too_short_for_the_intensity():
    from doefab.errors import DoefabError
    from doefab.optics.propagators.spectral import band_limited_pixel_matrix

    with pytest.raises(DoefabError, match="at least twice"):
        band_limited_pixel_matrix(np.array([0.0, 1e-6]), 8, 15, 1e-5, 5e-7, 0.02, 1e-6)


def test_spectral_buffers_kept_over_calls_give_each_pupil_its_own_intensity(monkeypatch):
    """The spectral route's reused buffers (a ``scratch`` kept over calls, and within one call over its plane
    batches) give what a fresh zero-padded transform per batch gives, bit for bit: for pupils of two shapes whose
    padded canvases have one size (a buffer of the larger pupil would leave its last column in the smaller one's
    canvas), for new pupil values in a buffer used before, and for a batch remainder."""
    from doefab.optics.propagators import base
    from doefab.optics.propagators.spectral import SpectralRoute

    route, rng = SpectralRoute(), np.random.default_rng(4)

    def setup(nx):
        x = (np.arange(nx) - nx / 2) * 5.4e-6
        return FocalSetup(x, x[:24][::-1].copy(), 5.4e-6, True, (550e-9,), 10e-3, 5.4e-6, 9)

    def pupil(nx, planes=5):
        return torch.from_numpy(rng.normal(size=(planes, 24, nx)) + 1j * rng.normal(size=(planes, 24, nx))).to(
            torch.complex64)

    wide, narrow = setup(30), setup(29)
    assert route.sizes(wide) == route.sizes(narrow)  # one canvas size for both
    monkeypatch.setattr(base, "BATCH_ELEMENTS", 2 * 48 * 60)  # batches of two planes and a remainder of one
    scratch, calls = {}, [(wide, pupil(30)), (narrow, pupil(29)), (wide, pupil(30)), (narrow, pupil(29, 1))]
    double = FocalSetup(wide.x, wide.y, 5.4e-6, True, (550e-9,), 10e-3, 5.4e-6, 9, real_dtype=torch.float64)
    calls.append((double, pupil(30).to(torch.complex128)))  # a double-precision pupil of a shape used before
    for s, p in calls:
        prepared = route.prepare(s)
        kept = route.intensity(p, 0, s, prepared, scratch=scratch)
        fresh = route.intensity(p.clone().requires_grad_(), 0, s, prepared).detach()  # a fresh copy per batch
        assert torch.equal(kept, fresh)
        assert torch.equal(route.intensity(p, 0, s, prepared), fresh)  # the buffers of one call
    assert len(scratch) == 3


def test_a_route_of_the_users_own_without_scratch_still_computes_psfs(small_camera, random_doe):
    """A Route object whose ``intensity`` takes the four arguments only (no ``scratch``) computes the PSFs the
    built-in route computes; a route whose signature cannot be read gets no scratch either."""
    from doefab.optics.propagators.base import scratch_kwargs
    from doefab.optics.propagators.spectral import SpectralRoute

    class Own:
        name = "own"

        def __init__(self):
            self.inner = SpectralRoute()

        def check(self, setup):
            self.inner.check(setup)

        def prepare(self, setup):
            return self.inner.prepare(setup)

        def intensity(self, pupil, index, setup, prepared):
            return self.inner.intensity(pupil, index, setup, prepared)

    zs, kw = [0.5, 2.0, math.inf], dict(kernel_size=31)
    own = doefab.split_aperture_psf(random_doe, small_camera, [450e-9, 650e-9], zs, route=Own(), **kw)
    ref = doefab.split_aperture_psf(random_doe, small_camera, [450e-9, 650e-9], zs, **kw)
    assert torch.equal(torch.as_tensor(own.coded), torch.as_tensor(ref.coded))
    assert scratch_kwargs(Own()) == {} and scratch_kwargs(SpectralRoute()) == {"scratch": {}}
    assert scratch_kwargs(type("Builtin", (), {"intensity": max})()) == {}  # max has no readable signature


def test_the_mft_routes_default_node_count_follows_the_fringes_per_pixel(small_camera):
    """With 2.6 fringe cycles per pixel (10.8 µm pixels, 1.08 mm pupil, 450 nm, 10 mm) two or four nodes per pixel
    leave the blank aperture's PSF several per cent off; the default takes as many as the fringes need and agrees
    with the spectral route, whose pixel integral is exact without a DOE."""
    from dataclasses import replace

    from doefab.optics.propagators.mft import auto_pixel_nodes

    cam = replace(small_camera, sensor_pitch=10.8e-6)
    kw = dict(kernel_size=21, precision="float64", halves=("coded", "uncoded"))
    spectral = doefab.split_aperture_psf(None, cam, [450e-9], [cam.focus_distance], **kw)
    auto = doefab.split_aperture_psf(None, cam, [450e-9], [cam.focus_distance], route="mft", **kw)
    for few in (2, 4):
        mft = doefab.split_aperture_psf(None, cam, [450e-9], [cam.focus_distance], route="mft", pixel_nodes=few, **kw)
        assert all(_rel(mft[half], spectral[half]) > 1e-2 for half in ("coded", "uncoded"))
    for half in ("coded", "uncoded"):
        assert _rel(auto[half], spectral[half]) < 1e-6
    setup = FocalSetup(x=np.arange(200) * 5.4e-6, y=np.arange(200) * 5.4e-6, pitch=5.4e-6, envelope=False,
                       wavelengths=(450e-9,),
                       sensor_distance=10e-3, sensor_pitch=10.8e-6, kernel_size=21)
    assert auto_pixel_nodes(setup) == math.ceil(2 * 10.8e-6 * 1.08e-3 / (450e-9 * 10e-3)) + 3  # 2c + 3: 9


def test_the_mft_route_refuses_fringes_beyond_its_node_cap_and_matrices_beyond_its_memory(small_camera):
    """200 µm pixels 10 mm behind a 1.08 mm pupil at 450 nm: c = 200e-6 · 1.08e-3 / (450e-9 · 10e-3) = 48 cycles per
    pixel would need 99 nodes, beyond the 64 the route takes; and a 100-byte budget refuses the matrices."""
    from dataclasses import replace

    from doefab.optics.propagators.mft import MFTRoute

    coarse = replace(small_camera, sensor_pitch=200e-6)
    with pytest.raises(SamplingError, match=r"\[mft\] the PSF has more than 30.5 fringe cycles per sensor pixel"):
        doefab.split_aperture_psf(None, coarse, [450e-9], [coarse.focus_distance], kernel_size=3, route="mft")
    with pytest.raises(SamplingError, match=r"\[mft\] the Fourier matrices of 1 band\(s\), a 21 px window and 6 nodes"):
        doefab.split_aperture_psf(None, small_camera, [450e-9], [small_camera.focus_distance], kernel_size=21,
                                  route=MFTRoute(max_bytes=100))


def test_the_full_pupil_is_the_pairs_system_as_one_pupil():
    """``"full"``: the coded half carries ``height`` (only its x < 0 half acts, as for the pair) and the plain half
    ``height_right``, one coherent pupil: near the axis its intensity lies between |√I_u − √I_c|² and
    (√I_u + √I_c)² of the two halves' PSFs (1 µm pixels sample the 14 µm lobes almost at points)."""
    cam = doefab.Camera(aperture_diameter=0.2e-3, doe_pitch=1e-6, doe_pixels=200, sensor_pitch=1e-6,
                        sensor_distance=5e-3, focus_distance=1.0)
    kw = dict(kernel_size=81, precision="float64", halves=("coded", "uncoded", "full"))
    h = doefab.blazed_grating_height(cam, 20, n_levels=4)  # first order 138 px off axis, out of the window
    left = h.copy()
    left[:, 100:] = 0.0
    whole = doefab.split_aperture_psf(h, cam, [550e-9], [cam.focus_distance], **kw)
    half = doefab.split_aperture_psf(left, cam, [550e-9], [cam.focus_distance], **kw)
    assert np.array_equal(whole.full.numpy(), half.full.numpy())
    box = (0, 0, slice(36, 45), slice(36, 45))
    iu, ic, full = (np.sqrt(whole[k][box].numpy()) for k in ("uncoded", "coded", "full"))
    assert np.all(full >= (iu - ic) * 0.99) and np.all(full <= (iu + ic) * 1.01)
    right = doefab.split_aperture_psf(None, cam, [550e-9], [cam.focus_distance], h_right=h, **kw)
    iu, ic, full = (np.sqrt(right[k][box].numpy()) for k in ("uncoded", "coded", "full"))
    assert np.all(full >= (ic - iu) * 0.99) and np.all(full <= (iu + ic) * 1.01)  # the grating on x > 0 now
