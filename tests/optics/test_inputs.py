"""Extreme and malformed inputs: one clear DoefabError (a ValueError) each, never a NaN PSF."""

import math

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError


@pytest.fixture(scope="module")
def cam():
    return doefab.Camera(aperture_diameter=20 * 5.4e-6, doe_pixels=24)


def test_nan_and_inf_heights(cam):
    h = np.zeros((24, 24))
    h[3, 4] = np.nan
    with pytest.raises(DoefabError, match="NaN or infinite"):
        doefab.split_aperture_psf(h, cam, [550e-9], [1.0])
    h[3, 4] = np.inf
    with pytest.raises(DoefabError, match="NaN or infinite"):
        doefab.split_aperture_psf(torch.from_numpy(h), cam, [550e-9], [1.0])


@pytest.mark.parametrize("shape", [(24, 23), (24,), (2, 24, 24)])
def test_wrong_shapes(cam, shape):
    with pytest.raises(DoefabError, match=r"has shape .* DOE grid is \(24, 24\)"):
        doefab.split_aperture_psf(np.zeros(shape), cam, [550e-9], [1.0])


def test_heights_in_wrong_unit(cam):
    with pytest.raises(DoefabError, match="metres"):
        doefab.split_aperture_psf(np.full((24, 24), 0.5), cam, [550e-9], [1.0])


@pytest.mark.parametrize("lams, msg", [([-550e-9], "positive"), ([0.0], "positive"), ([550.0], "metres"),
                                       ([], "empty"), ([float("nan")], "positive")])
def test_bad_wavelengths(cam, lams, msg):
    with pytest.raises(DoefabError, match=msg):
        doefab.split_aperture_psf(None, cam, lams, [1.0])


@pytest.mark.parametrize("depths, msg", [([0.0], "> 0"), ([-2.0], "> 0"), ([], "empty"), ([float("nan")], "> 0")])
def test_bad_depths(cam, depths, msg):
    with pytest.raises(DoefabError, match=msg):
        doefab.split_aperture_psf(None, cam, [550e-9], depths)


def test_bad_options(cam):
    with pytest.raises(DoefabError, match="kernel_size"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], kernel_size=0)
    with pytest.raises(DoefabError, match="halves"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], halves=("left",))
    with pytest.raises(DoefabError, match="unknown propagation route"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], route="magic")
    with pytest.raises(DoefabError, match="precision"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], precision="half")
    with pytest.raises(DoefabError, match="not computed"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], halves=("coded",))["uncoded"]


def test_extreme_but_valid_inputs_stay_finite(cam):
    h = np.full((24, 24), 1e-4)  # 100 µm of glass: many waves, still a valid height
    pair = doefab.split_aperture_psf(h, cam, [400e-9, 2e-6], [1e-2, 1e6, math.inf], kernel_size=105,
                                     pupil_oversample=2)
    for t in (pair.coded, pair.uncoded):
        assert torch.isfinite(t).all() and (t >= -1e-9).all()


@pytest.mark.parametrize("lams", [np.array([550e-9], np.float16), torch.tensor([550e-9], dtype=torch.float16),
                                  torch.tensor([550e-9], dtype=torch.bfloat16), [np.float16(550e-9)]])
def test_half_precision_wavelengths_are_refused_before_they_are_used(cam, lams):
    """float16 has no normal number below 6.1e-5: 550e-9 m arrives as 536 nm, already rounded. float32 keeps 24
    bits: its PSF is the float64 one."""
    assert float(np.float16(550e-9)) == pytest.approx(5.36e-7, rel=1e-3)
    with pytest.raises(DoefabError, match=r"wavelengths? is half precision .*pass float32 or float64"):
        doefab.split_aperture_psf(None, cam, lams, [1.0], kernel_size=5)
    single = doefab.split_aperture_psf(None, cam, np.array([550e-9], np.float32), [1.0], kernel_size=5)
    double = doefab.split_aperture_psf(None, cam, [550e-9], [1.0], kernel_size=5)
    assert torch.allclose(single.coded, double.coded, rtol=1e-5, atol=1e-9)


def test_half_precision_depths_and_heights_are_refused(cam):
    with pytest.raises(DoefabError, match="depths is half precision"):
        doefab.split_aperture_psf(None, cam, [550e-9], np.array([2.7], np.float16), kernel_size=5)
    h = np.full((24, 24), 1e-7)
    for half in (h.astype(np.float16), torch.from_numpy(h).half(), torch.from_numpy(h).bfloat16()):
        with pytest.raises(DoefabError, match=r"height is half precision .*pass float32 or float64"):
            doefab.split_aperture_psf(half, cam, [550e-9], [1.0], kernel_size=5)


@pytest.mark.parametrize("call, name", [
    (lambda cam: doefab.split_aperture_psf(None, cam, [550e-9], [1.0], kernel_size=True), "kernel_size"),
    (lambda cam: doefab.split_aperture_psf(None, cam, [550e-9], [1.0], kernel_size=5, route="mft",
                                           pixel_nodes=True), "pixel_nodes"),
    (lambda cam: doefab.split_aperture_psf(None, cam, [550e-9], [1.0], kernel_size=5, route="fft",
                                           oversample=True), "oversample"),
    (lambda cam: doefab.blazed_grating_height(cam, direction=True), "direction"),
])
def test_a_boolean_is_not_taken_for_a_number(cam, call, name):
    with pytest.raises(DoefabError, match=rf"{name} must be .*got True"):
        call(cam)
    assert doefab.split_aperture_psf(None, cam, [550e-9], [1.0], kernel_size=np.int64(5)).coded.shape[-1] == 5


def test_fabricated_height_gives_the_unit_error(tiny_camera):
    levels = np.zeros((tiny_camera.doe_pixels,) * 2, np.uint8)
    with pytest.raises(DoefabError, match="550 nm is 5.5e-07 m"):
        doefab.fabricated_height(levels, tiny_camera, design_wavelength=550)
    with pytest.raises(DoefabError, match="550 nm is 5.5e-07 m"):
        doefab.Camera(design_wavelength=550)


def test_options_wavelength_tensors_and_units_each_get_their_own_error(cam):
    """A mistyped route option names the route and what it takes; a wavelength tensor under autograd says the PSF
    is differentiable in the heights only; a material's index refuses nanometres; a gap model takes a numpy map."""
    with pytest.raises(DoefabError, match=r"unknown option pixelnodes: .* the 'mft' route's \(pixel_nodes, max"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], route="mft", pixelnodes=3)
    with pytest.raises(DoefabError, match=r"unknown option pixel_nodes: .* the 'spectral' route's \(it has none\)"):
        doefab.split_aperture_psf(None, cam, [550e-9], [1.0], pixel_nodes=3)
    with pytest.raises(DoefabError, match="requires grad: the PSF is differentiable in the height maps only"):
        doefab.split_aperture_psf(None, cam, torch.tensor([550e-9], requires_grad=True), [1.0])
    with pytest.raises(DoefabError, match=r"wavelengths are in metres \(550 nm is 5.5e-07 m\)"):
        doefab.FUSED_SILICA.index([500e-9, 550])
    assert doefab.FUSED_SILICA.height_2pi(550e-9) == pytest.approx(550e-9 / (1.459911 - 1), rel=1e-5)  # Malitson
    t = doefab.gap_transmittance(np.zeros((24, 24)), cam, 550e-9, math.inf, 1e-3)
    assert torch.allclose(t.abs(), torch.ones(24, 24, dtype=torch.float64))  # a flat plate moves no light


def test_numpy_scalars_make_the_same_camera_as_python_numbers():
    a = doefab.Camera(doe_pitch=np.float64(5.4e-6), doe_pixels=np.int64(1600), sensor_distance=np.float32(0.05))
    b = doefab.Camera(doe_pitch=5.4e-6, doe_pixels=1600, sensor_distance=float(np.float32(0.05)))
    assert a == b and hash(a) == hash(b) and type(a.doe_pixels) is int and type(a.doe_pitch) is float
    with pytest.raises(DoefabError, match="half precision"):
        doefab.Camera(doe_pitch=np.float16(5.4e-6))
