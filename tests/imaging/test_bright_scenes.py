"""A scene far brighter than full scale (a lamp, the sun's disc): where no PSF reaches, the captures stay dark. In
float32 the FFT's rounding spreads about 1e-9 of the brightest point over the whole frame, which at 1e5 is 1e-4 of
full scale in pixels whose true value is 0 (a float64 convolution here: at most 1e-11)."""

import numpy as np
import pytest

import doefab


@pytest.fixture(scope="module")
def pair():
    cam = doefab.Camera(doe_pixels=256, doe_pitch=33.75e-6)
    return doefab.split_aperture_psf(None, cam, [650e-9, 550e-9, 450e-9], [cam.focus_distance], kernel_size=31)


@pytest.mark.parametrize("radiance", [1e2, 1e5, 1e6])
def test_light_does_not_reach_where_no_psf_does(pair, radiance):
    scene = np.zeros((3, 128, 128))
    scene[:, 4, 4] = radiance  # a point in one corner; the PSFs reach 15 px from it
    scene[:, 100:110, 100:110] = 0.2  # a dim patch in the other
    coded, uncoded = doefab.simulate_captures(scene, pair, noise="none")
    for view in (coded, uncoded):
        far = np.asarray(view)[:, 40:80, 40:80]  # beyond 15 px of the point and of the patch: no light
        assert float(np.abs(far).max()) < 1e-6, radiance
        # the patch's interior is flat in each band (its PSF's light, about half the radiance, in every pixel)
        inner = np.asarray(view)[:, 104:106, 104:106]
        assert np.allclose(inner, inner.mean(axis=(1, 2), keepdims=True), rtol=1e-4)
