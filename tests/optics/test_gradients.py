import math

import numpy as np
import torch

import doefab


def test_gradcheck_small_float64():
    cam = doefab.Camera(aperture_diameter=8 * 5.4e-6 * 1.9, doe_pitch=5.4e-6, doe_pixels=16, sensor_pitch=5.4e-6,
                        sensor_distance=2e-3, focus_distance=1.0)
    plan = doefab.PSFPlan(cam, [500e-9, 600e-9], [math.inf, 0.5], kernel_size=5, precision="float64")
    rng = np.random.default_rng(1)
    h_um = torch.tensor(rng.uniform(0, 1.2, (16, 16)), dtype=torch.float64, requires_grad=True)

    def fn(hu):
        pair = plan(hu * 1e-6)
        return torch.cat([pair.coded.flatten(), pair.uncoded.flatten()])

    assert torch.autograd.gradcheck(fn, (h_um,), eps=1e-6, atol=1e-7, rtol=1e-4)


def test_gradient_only_on_the_coded_half():
    cam = doefab.Camera(aperture_diameter=20 * 5.4e-6, doe_pixels=24)
    plan = doefab.PSFPlan(cam, [550e-9], [cam.focus_distance], kernel_size=7, halves=("coded",))
    h = torch.full((24, 24), 3e-7, requires_grad=True)
    h.data += torch.rand(24, 24) * 1e-7
    plan(h).coded.sum().backward()
    g = h.grad.numpy()
    assert np.abs(g[:, :12]).max() > 0
    assert np.all(g[:, 12:] == 0)  # the right half never touches the coded PSF
