"""Physics references: every expected value is analytic or an independent computation."""

import math

import numpy as np
import pytest
from scipy import integrate
from scipy.special import j0, j1

import doefab


def _pixel_integrate(func, centres_x, centres_y, pitch, nodes=16):
    """Integrate a 2-D function over square pixels with Gauss–Legendre (independent of doefab)."""
    t, w = np.polynomial.legendre.leggauss(nodes)
    t, w = t / 2, w / 2
    ux = (centres_x[:, None] + pitch * t[None, :]).ravel()
    uy = (centres_y[:, None] + pitch * t[None, :]).ravel()
    vals = func(ux[None, :], uy[:, None]).reshape(len(centres_y), nodes, len(centres_x), nodes)
    return np.einsum("iajb,a,b->ij", vals, w, w) * pitch**2


def test_airy_pattern_full_aperture_default_camera():
    cam = doefab.Camera()
    lam, k = 550e-9, 63
    pair = doefab.split_aperture_psf(None, cam, [lam], [cam.focus_distance], kernel_size=k, halves=("full",),
                                     precision="float64")
    psf = pair.full[0, 0].numpy()
    s, d, p = cam.sensor_distance, cam.aperture_diameter, cam.sensor_pitch
    peak = (math.pi * d**2 / 4) / (lam * s) ** 2  # intensity per m² at the centre for unit energy

    def airy(u, v):
        x = math.pi * d * np.hypot(u, v) / (lam * s)
        with np.errstate(all="ignore"):
            val = np.where(x == 0, 1.0, (2 * j1(x) / x) ** 2)
        return peak * val

    c = (np.arange(k) - k // 2) * p
    ref = _pixel_integrate(airy, c, c, p, nodes=20)
    assert np.linalg.norm(psf - ref) / np.linalg.norm(ref) < 1e-3
    assert np.abs(psf - ref).max() / ref.max() < 1e-3


def test_airy_first_zero_position(small_camera):
    # sample the intensity finely (pixel pitch 1/20 of the Airy radius, one node) and find the first minimum
    lam = 600e-9
    zero = 1.22 * lam * small_camera.sensor_distance / small_camera.aperture_diameter
    fine = small_camera.replace(sensor_pitch=zero / 40)
    k = 201
    psf = doefab.split_aperture_psf(None, fine, [lam], [fine.focus_distance], kernel_size=k, halves=("full",),
                                    precision="float64", route="mft", pixel_nodes=1).full[0, 0].numpy()
    row = psf[k // 2, k // 2:]
    first_min = np.argmax((row[1:-1] < row[:-2]) & (row[1:-1] < row[2:])) + 1
    # parabolic refinement of the sampled minimum
    y0, y1, y2 = row[first_min - 1: first_min + 2]
    pos = (first_min + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)) * fine.sensor_pitch
    assert pos == pytest.approx(zero, rel=0.01)


def test_half_energy_and_blank_mirror():
    cam = doefab.Camera()
    pair = doefab.split_aperture_psf(doefab.blank_height(cam), cam, [656e-9, 486e-9], [math.inf, 2.0, 5.0],
                                     kernel_size=255)
    for half in ("coded", "uncoded"):
        sums = pair[half].sum(dim=(-1, -2)).numpy()
        assert np.all(np.abs(sums - 0.5) < 0.01), sums
    coded, uncoded = pair.coded.numpy(), pair.uncoded.numpy()
    assert np.abs(coded[..., ::-1] - uncoded).max() < 1e-6 * uncoded.max()


@pytest.mark.parametrize("levels", [2, 4, 8, 16])
def test_quantized_blazed_grating_efficiency_and_position(levels):
    cam = doefab.Camera()
    lam, k = cam.design_wavelength, 41
    s = cam.sensor_distance
    period = 16 * cam.doe_pitch
    u1 = s * math.tan(math.asin(lam / period))  # grating equation + geometry
    h = doefab.blazed_grating_height(cam, 16, n_levels=levels)
    kw = dict(kernel_size=k, halves=("coded",), precision="float64")
    spot = doefab.split_aperture_psf(h, cam, [lam], [cam.focus_distance], center=(u1, 0.0), **kw).coded[0, 0]
    # the first order has the shape of the blank half-aperture PSF: its window energy normalises the box
    blank = doefab.split_aperture_psf(None, cam, [lam], [cam.focus_distance], **kw).coded[0, 0]
    eff = float(spot.sum() / blank.sum())
    assert eff == pytest.approx(np.sinc(1 / levels) ** 2, abs=0.01)
    c = np.arange(k) - k // 2
    offset_px = float((spot.numpy().sum(0) * c).sum() / spot.numpy().sum())
    assert abs(offset_px) < 0.1


def test_defocus_matches_independent_hankel_transform(small_camera):
    """Full pupil, point at 2 m, camera focused at 5 m: exact spherical defocus vs a 1-D Hankel integral."""
    cam, lam, z, k = small_camera, 500e-9, 0.3, 31
    psf = doefab.split_aperture_psf(None, cam, [lam], [z], kernel_size=k, halves=("full",),
                                    precision="float64", pupil_oversample=2).full[0, 0].numpy()
    s, a = cam.sensor_distance, cam.aperture_diameter / 2
    kk = 2 * math.pi / lam

    def opd(r):
        return (np.sqrt(r * r + z * z) - z) - (np.sqrt(r * r + cam.focus_distance**2) - cam.focus_distance)

    rho = np.linspace(0, (k / 2 + 1) * cam.sensor_pitch * math.sqrt(2), 400)
    rr = np.linspace(0, a, 4001)
    field = np.array([integrate.simpson(np.exp(1j * kk * opd(rr)) * j0(2 * math.pi * rr * q / (lam * s)) * rr,
                                        x=rr) for q in rho]) * 2 * math.pi / (lam * s)
    inten = np.abs(field) ** 2 / (math.pi * a * a)

    def radial(u, v):
        return np.interp(np.hypot(u, v), rho, inten)

    c = (np.arange(k) - k // 2) * cam.sensor_pitch
    ref = _pixel_integrate(radial, c, c, cam.sensor_pitch, nodes=8)
    assert np.linalg.norm(psf - ref) / np.linalg.norm(ref) < 5e-3


def test_uncoded_defocus_centroid_follows_geometric_optics():
    """A near point images behind the sensor: the right half's blur sits at +x, centroid 4ρ/(3π)."""
    cam, lam, z, k = doefab.Camera(), 550e-9, 1.0, 129
    psf = doefab.split_aperture_psf(None, cam, [lam], [z], kernel_size=k, halves=("uncoded",)).uncoded[0, 0]
    psf = psf.numpy()
    f, s = cam.focal_length, cam.sensor_distance
    s_img = 1 / (1 / f - 1 / z)
    rho = cam.aperture_diameter / 2 * (s_img - s) / s_img  # geometric blur radius on the sensor
    c = (np.arange(k) - k // 2) * cam.sensor_pitch
    cx = (psf.sum(0) * c).sum() / psf.sum()
    cy = (psf.sum(1) * -c).sum() / psf.sum()
    assert cx == pytest.approx(4 * rho / (3 * math.pi), rel=0.05)
    assert abs(cy) < 0.05 * rho


@pytest.mark.parametrize("step", [0.5, 0.9])
def test_a_structured_doe_out_of_focus_is_off_by_the_staircase_estimate(step):
    """One pupil sample per DOE pixel holds the point's wavefront flat over each pixel: the half-ring's start at a
    plane whose wavefront steps ``step`` rad per pixel at the rim is off from the limit of finer sampling
    (Richardson, q = 2 and 4) by step² / (12 √3) (``staircase_error``) within 20 %, at the steps where the 1 %
    warning acts (from 0.456 rad; below it a part linear in the step adds, which the estimate leaves out: the
    benchmark's table); the plain half, a sampled smooth wavefront with no envelope, by less than a quarter of it.
    The depth comes from the exact spherical wavefront's rim slope, 2π p / λ · |a/√(a² + z²) − a/√(a² + f²)|."""
    from doefab.optics.psf import staircase_error
    from doefab.tasks.halfring import HalfRingTask

    lam, focus, p = 486e-9, 3.5, 8.64e-3 / 512
    cam = doefab.Camera(doe_pixels=128, doe_pitch=p, aperture_diameter=128 * p, focus_distance=focus)
    h = HalfRingTask().init_height(cam, np.random.default_rng(0))
    a = cam.aperture_diameter / 2
    c = step * lam / (2 * math.pi * p) + a / math.hypot(a, focus)
    z = a * math.sqrt(1 / c**2 - 1)

    def error(half):
        psf = {q: getattr(doefab.split_aperture_psf(h, cam, [lam], [z], kernel_size=101, halves=(half,),
                                                    precision="float64", pupil_oversample=q), half)[0, 0].numpy()
               for q in (1, 2, 4)}
        ref = (4 * psf[4] - psf[2]) / 3
        return np.linalg.norm(psf[1] - ref) / np.linalg.norm(ref)

    assert error("coded") == pytest.approx(staircase_error(step), rel=0.2)
    assert error("uncoded") < 0.25 * staircase_error(step)
