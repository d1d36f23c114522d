"""End-to-end fine-tuning: the depth loss reaches the DOE, runs resume, outputs load."""

import numpy as np
import pytest
import torch

import doefab
from doefab.reconstruction.endtoend import finetune_end_to_end, render_depth_batch


@pytest.fixture(scope="module")
def radial_design(tmp_path_factory):
    d = doefab.optimize("half-ring", iterations=1, parameterization="radial", knots=40, sampling=4, progress=False,
                        task_params={"z_step": 2.0})
    folder = tmp_path_factory.mktemp("e2e") / "design"
    d.save(folder)
    return folder


def test_depth_loss_gradient_reaches_the_psf():
    k = 9
    psf = torch.full((2, 3, k, k), 0.5 / k**2, requires_grad=True)
    c, u, d = render_depth_batch([0], "train", 64, psf, psf.detach(), (2.0, 4.0), margin=k // 2, noise_seed=0)
    assert c.shape == (1, 3, 64, 64) and d.shape == (1, 64, 64)
    (c * torch.randn_like(c)).sum().backward()
    assert psf.grad is not None and float(psf.grad.abs().sum()) > 0


def test_finetune_moves_the_doe_resumes_and_writes_loadable_outputs(radial_design, tmp_path):
    out = tmp_path / "run"
    kw = dict(minutes=10, doe_every=1, sampling=4, crop=64, val_images=1, batch=1, val_every=1, progress=False,
              lr_doe=0.05)
    res = finetune_end_to_end(radial_design, out, max_steps=2, **kw)
    assert res["steps"] == 2 and np.isfinite(res["val_mae_end_m"])
    new = doefab.Design.load(out / "design")
    start = doefab.Design.load(radial_design)
    assert new.extra["end_to_end"]["steps"] == 2
    assert not np.array_equal(new.levels, start.levels)  # the depth loss moved the DOE
    more = finetune_end_to_end(radial_design, out, max_steps=3, resume=True, **kw)
    assert more["steps"] == 3
    rec = doefab.load_reconstructor("depth", weights_dir=out / "weights", design=out / "design")
    pred = rec(np.zeros((3, 64, 64), np.float32), np.zeros((3, 64, 64), np.float32))
    assert np.asarray(pred).shape == (64, 64)


def test_finetune_renders_with_the_sensors_noise(radial_design, tmp_path, monkeypatch):
    """``sensor``'s full well and read noise reach the rendered captures (the first, validation batch)."""
    import doefab.reconstruction.endtoend as e2e
    from doefab.imaging.sensor import Sensor

    seen = {}

    class Stop(Exception):
        pass

    def spy(*args, **kw):
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(e2e, "render_depth_batch", spy)
    with pytest.raises(Stop):
        finetune_end_to_end(radial_design, tmp_path / "run", minutes=10, sampling=4, crop=64, val_images=1, batch=1,
                            progress=False, max_steps=1, sensor=Sensor(full_well_e=900.0, read_noise_e=7.0))
    assert (seen["full_well"], seen["read_noise"]) == (900.0, 7.0)


def test_rendered_depth_captures_carry_the_poisson_gaussian_variance():
    """A flat grey scene through a delta PSF: the capture's variance is x / N_fw + (σ_read / N_fw)²."""
    k = 9
    psf = torch.zeros((2, 3, k, k))
    psf[:, :, k // 2, k // 2] = 1.0
    c, _, _ = render_depth_batch([0], "train", 64, psf, psf, (2.0, 4.0), margin=k // 2, noise_seed=0,
                                 full_well=400.0, read_noise=8.0)
    clean, _, _ = render_depth_batch([0], "train", 64, psf, psf, (2.0, 4.0), margin=k // 2, noise_seed=0,
                                     full_well=1e12, read_noise=0.0)
    resid = (c - clean).numpy()
    want = clean.numpy() / 400.0 + (8.0 / 400.0) ** 2
    inside = (clean.numpy() > 0.05) & (clean.numpy() < 0.9)  # not clipped at 0 or 1
    assert np.mean(resid[inside] ** 2) == pytest.approx(np.mean(want[inside]), rel=0.05)


@pytest.mark.parametrize("n_levels", [8, 32])
def test_a_pixel_start_reads_each_level_as_its_fraction_of_a_wave(tiny_camera, n_levels):
    from doefab.design.design import Design
    from doefab.reconstruction.endtoend import _start_theta

    n = tiny_camera.doe_pixels
    lv = np.zeros((n, n), np.uint8)
    lv[: n // 2] = 3  # level 3 of L: 3/L of a wave at the design wavelength; level 0 none
    d = Design(task="half-ring", task_params={}, camera=tiny_camera, wavelengths=(550e-9,), depths=(2.0,),
               height=doefab.levels_to_height(lv, tiny_camera, n_levels), levels=lv, n_levels=n_levels,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    theta, _ = _start_theta(d, "pixel", tiny_camera, 1)
    assert theta.shape == (n, n)
    np.testing.assert_allclose(theta[: n // 2].numpy(), 3 / n_levels, atol=1e-6)
    np.testing.assert_allclose(theta[n // 2:].numpy(), 0.0, atol=1e-6)
