"""The same numbers on every device: each computation on a device against the same computation on the CPU.

Each case runs twice: ``device=None`` (the default device, which tests not marked ``cuda`` pin to the CPU through
``$DOEFAB_DEVICE``: it must equal ``device="cpu"`` bit for bit — the CPU results are unchanged) and ``device="cuda"`` (marked ``cuda``: ``pytest -m
cuda tests/`` runs these alone), which must agree with the CPU to float32 rounding and is skipped, with the reason,
where torch sees no CUDA device. What leaves the API is on the CPU (numpy, or a tensor on its input's device).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import doefab
from doefab._devices import resolve_device
from doefab.tolerance.errors import PartErrors

CUDA = [pytest.mark.cuda, pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")]
DEVICES = [pytest.param(None, id="auto"), pytest.param("cuda", marks=CUDA, id="cuda")]
RGB = [650e-9, 550e-9, 450e-9]


def agree(device, got, want, rtol: float, atol: float = 0.0) -> None:
    """``got`` (computed on ``device``) is ``want`` (the CPU's): bit for bit where ``device`` is the CPU, else
    within ``rtol`` and ``atol`` (NaN where the CPU has NaN: a metric not yet measured)."""
    got, want = (torch.as_tensor(np.asarray(x)) if not isinstance(x, torch.Tensor) else x.detach().cpu()
                 for x in (got, want))
    exact = resolve_device(device).type == "cpu"
    torch.testing.assert_close(got, want, rtol=0 if exact else rtol, atol=0 if exact else atol, equal_nan=True)


# ---------------------------------------------------------------- PSFs

FINE = doefab.Camera(aperture_diameter=0.2e-3, doe_pitch=1e-6, doe_pixels=200, sensor_pitch=1e-6,
                     sensor_distance=5e-3, focus_distance=1.0)  # resolves its lens sphere: every route is valid


@pytest.mark.parametrize("route", ["spectral", "mft", "fft", "asm"])
@pytest.mark.parametrize("device", DEVICES)
def test_psfs_of_every_route(route, device):
    h = doefab.blazed_grating_height(FINE, 100, n_levels=8)
    options = {"oversample": 0.5} if route == "fft" else {}  # the default 4 samples per pixel: a 11000² FFT here
    kw = dict(kernel_size=41, halves=("coded", "uncoded"), route=route, **options)
    want = doefab.split_aperture_psf(h, FINE, [550e-9, 450e-9], [1.0, math.inf], device="cpu", **kw)
    got = doefab.split_aperture_psf(h, FINE, [550e-9, 450e-9], [1.0, math.inf], device=device, **kw)
    for half in ("coded", "uncoded"):
        assert got[half].device.type == "cpu"  # numpy in: the pair on the CPU
        agree(device, got[half], want[half], rtol=1e-4, atol=1e-5 * float(want[half].max()))


@pytest.mark.parametrize("device", DEVICES)
def test_psf_gradients_stay_on_the_heights_device(device):
    """A height tensor on the device gives its PSFs and their gradient there (the optimiser's path)."""
    cam = doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=20e-3, focus_distance=5.0)
    h0 = torch.from_numpy(doefab.blazed_grating_height(cam, 8))
    weight = torch.linspace(0, 1, 31 * 31).reshape(31, 31)

    def run(dev):
        plan = doefab.PSFPlan(cam, RGB, [5.0, 2.0], 31, halves=("coded",), device=dev)
        h = h0.to(plan.device).requires_grad_(True)
        psf = plan(h).coded
        assert psf.device == h.device
        (psf * weight.to(psf.device)).sum().backward()
        return psf, h.grad

    (psf, grad), (psf0, grad0) = run(device), run("cpu")
    agree(device, psf, psf0, rtol=1e-4, atol=1e-5 * float(psf0.detach().max()))
    agree(device, grad, grad0, rtol=1e-3, atol=1e-4 * float(grad0.abs().max()))


@pytest.mark.parametrize("device", DEVICES)
def test_psfs_through_a_gap(device):
    cam = doefab.Camera(aperture_diameter=128 * 5.4e-6, doe_pixels=128, doe_pitch=5.4e-6)
    h = np.random.default_rng(1).integers(0, 16, (128, 128)) * 7.5e-8
    want = doefab.PSFPlan(cam, [550e-9, 650e-9], [2.0, math.inf], 31, device="cpu")(h, gap=5e-3)
    got = doefab.PSFPlan(cam, [550e-9, 650e-9], [2.0, math.inf], 31, device=device)(h, gap=5e-3)
    for half in ("coded", "uncoded"):
        agree(device, got[half], want[half], rtol=1e-4, atol=1e-5 * float(want[half].max()))


# ---------------------------------------------------------------- design

@pytest.mark.parametrize("optimizer, param", [("adam", "pixel"), ("lbfgs", "pixel"), ("adam", "radial")])
@pytest.mark.parametrize("device", DEVICES)
def test_a_few_design_steps(device, optimizer, param, tiny_camera, request):
    if device == "cuda" and (optimizer, param) != ("adam", "pixel"):
        request.applymarker(pytest.mark.xfail(strict=False, reason=(
            "on an H100 (torch 2.11+cu130) the L-BFGS and radial trajectories left rtol 2e-3 within 4 steps: the "
            "line search and the radial profile amplify float32 rounding; their bound is not measured yet")))
    kw = dict(iterations=4, optimizer=optimizer, camera=tiny_camera, progress=False, parameterization=param,
              task_params={"kernel_size": 15, "arm_px": 4}, qat_fraction=0.25, eval_every=1)
    want = doefab.optimize("streak", device="cpu", **kw)
    got = doefab.optimize("streak", device=device, **kw)
    hist, hist0 = (torch.tensor([[r[0], r[2], r[3]] for r in d.history], dtype=torch.float64) for d in (got, want))
    agree(device, hist[:1], hist0[:1], rtol=1e-5)  # the starting point's loss and metric
    agree(device, hist, hist0, rtol=2e-3)  # then the steps taken from gradients computed there
    agree(device, torch.tensor(got.metrics["per_entry"]["continuous"]),
          torch.tensor(want.metrics["per_entry"]["continuous"]), rtol=2e-3)


# ---------------------------------------------------------------- captures

def _scene(rng, c=3, size=48):
    s = rng.uniform(0.0, 0.8, (c, size, size))
    s[:, 20:24, 20:24] = 30.0  # a highlight: the tails of the PSF matter
    return s


@pytest.mark.parametrize("device, noise", [(None, "none"), (None, "default"),
                                           pytest.param("cuda", "none", marks=CUDA, id="cuda-none")])
def test_captures(device, noise, small_camera):
    """The blur on the device; the noise is drawn on the CPU from the seed, the same on every device (its rejection
    sampler draws a Poisson count from the blurred value, so a GPU's blur, equal to float32 rounding, may change
    which numbers follow: the GPU is compared without noise)."""
    rng = np.random.default_rng(2)
    h = doefab.blazed_grating_height(small_camera, 12)
    pair = doefab.split_aperture_psf(h, small_camera, RGB, [2.0, 5.0], 21, device="cpu")
    depth = rng.choice([2.0, 4.5], (48, 48))  # on and between the planes
    kw = dict(scene=_scene(rng), pair=pair, depth_map=depth, noise=noise, seed=3)
    want, got = doefab.simulate_captures(**kw, device="cpu"), doefab.simulate_captures(**kw, device=device)
    for g, w in zip(got, want):
        assert isinstance(g, np.ndarray) and g.dtype == np.float32
        agree(device, g, w, rtol=0, atol=1e-5)


# ---------------------------------------------------------------- networks

@pytest.fixture(scope="module")
def tiny_hdr(tmp_path_factory, small_camera):
    """``(pair, patch)``: an RGB PSF pair of a small camera standing in for the committed HDR design's (which takes a
    minute to compute) and ``patch(monkeypatch)`` that makes training and loading use it."""
    h = doefab.blazed_grating_height(small_camera, 12)
    pair = doefab.split_aperture_psf(h, small_camera, [656e-9, 589e-9, 486e-9], [5.0], 15, device="cpu")

    def patch(mp):
        import doefab.reconstruction.loader as loader
        import doefab.reconstruction.train as train

        for module in (loader, train):
            mp.setattr(module, "psf_pair", lambda task, design=None: (pair, "tiny"))
    return pair, patch


ARCH = {"features": 1, "width": 4, "highlight_iters": 1, "bound_iters": 0}  # fast steps


def _train(tmp, device, patch):
    from doefab.reconstruction.train import train

    with pytest.MonkeyPatch.context() as mp:
        patch(mp)
        return train("hdr", "proposed", minutes=5, out_dir=tmp / "run", weights_dir=tmp / "w", crop=64, batch=2,
                     val_images=1, val_every=2, max_steps=2, arch=ARCH, progress=False, device=device)


@pytest.fixture(scope="module")
def cpu_run(tmp_path_factory, tiny_hdr):
    """(folder, record) of the two training steps on the CPU."""
    root = tmp_path_factory.mktemp("cpu")
    return root, _train(root, "cpu", tiny_hdr[1])


@pytest.mark.parametrize("device", DEVICES)
def test_a_few_training_steps(device, tiny_hdr, cpu_run, tmp_path):
    (root, want), got = cpu_run, _train(tmp_path, device, tiny_hdr[1])
    rows = [np.loadtxt(d / "run" / "history.csv", delimiter=",", skiprows=1) for d in (tmp_path, root)]
    agree(device, rows[0][:, [0, 2, 3]], rows[1][:, [0, 2, 3]], rtol=2e-3)  # step, loss, validation PSNR
    state = [torch.load(d / "w" / "hdr_proposed.pt", weights_only=True) for d in (tmp_path, root)]
    assert all(t.device.type == "cpu" for t in state[0].values())  # the file holds CPU tensors
    for k in state[1]:
        agree(device, state[0][k], state[1][k], rtol=0, atol=8e-3)  # two Adam steps (lr 1e-3) either way, at most
    if resolve_device(device).type == "cpu":
        assert got["weights_sha256"] == want["weights_sha256"]


@pytest.mark.parametrize("device", DEVICES)
def test_a_reconstructor_forward(device, tiny_hdr, cpu_run):
    (pair, patch), (root, _) = tiny_hdr, cpu_run
    rng = np.random.default_rng(4)
    coded, uncoded = doefab.simulate_captures(_scene(rng, size=64), pair, seed=1, device="cpu")
    with pytest.MonkeyPatch.context() as mp:
        patch(mp)
        ref = doefab.load_reconstructor("hdr", weights_dir=root / "w", device="cpu")
        rec = doefab.load_reconstructor("hdr", weights_dir=root / "w", device=device)
    assert next(rec.model.parameters()).device.type == resolve_device(device).type
    want = ref(coded, uncoded)
    got = rec(coded, uncoded)
    assert isinstance(got, np.ndarray)
    # cuDNN and the CPU sum a deep network's convolutions in other orders: on an H100 the largest difference was
    # 3.0e-5 of the output's range (2 of 12 288 values beyond 1e-5)
    agree(device, got, want, rtol=1e-4, atol=1e-4 * float(np.abs(want).max()))
    dev = resolve_device(device)
    out = rec(torch.from_numpy(np.asarray(coded)).to(dev), torch.from_numpy(np.asarray(uncoded)).to(dev), psf=pair)
    assert out.device.type == dev.type  # torch in: on the captures' device
    agree(device, out, ref(coded, uncoded, psf=pair), rtol=1e-4, atol=1e-4 * float(np.abs(want).max()))


# ---------------------------------------------------------------- tolerance

PART = PartErrors(overlay=((0.4e-6, -0.2e-6),) * 4, mount_shift=(17.3e-6, -4.1e-6), mount_rotation=2e-3,
                  depth_scale=(1.03, 0.98, 1.01, 0.99), edge_bias=0.1e-6, roughness=3e-9, seed=2,
                  crosstalk=(0.05, 0.04), calibrated=True)


@pytest.mark.parametrize("device", DEVICES)
def test_a_judged_part(device, grating_design):
    from doefab.tolerance.judge import PSFJudge

    folder = grating_design(80, 31, seed=1)
    judges = PSFJudge(folder, device="cpu"), PSFJudge(folder, device=device)
    want, got = (j.psfs(PART, halves=("coded", "uncoded")) for j in judges)
    for half in ("coded", "uncoded"):
        assert got[half].device.type == "cpu"
        agree(device, got[half], want[half], rtol=1e-4, atol=1e-5 * float(want[half].max()))
    score, score0 = (j.evaluate(PART) for j in judges)
    agree(device, torch.tensor(list(score.values())), torch.tensor(list(score0.values())), rtol=1e-4)


# ---------------------------------------------------------------- end to end (GPU only: the CPU's own run is
# tests/reconstruction/test_endtoend.py's)

@pytest.mark.parametrize("device", [pytest.param("cuda", marks=CUDA, id="cuda")])
def test_two_end_to_end_steps(device, tmp_path, monkeypatch):
    from doefab.design.design import Design
    from doefab.tasks.halfring import HalfRingTask

    cam = doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=20e-3, focus_distance=3.5)
    task = HalfRingTask(kernel_size=31, z_step=2.0)  # three planes
    task.bind(cam)
    lv = doefab.quantize_levels(task.init_height(cam, np.random.default_rng(0)), cam)
    lv[:, 50:] = 15
    Design(task="half-ring", task_params=task.params(), camera=cam, wavelengths=task.wavelengths(cam),
           depths=task.depths(cam), height=doefab.levels_to_height(lv, cam), levels=lv,
           metrics={"name": "m", "continuous": 0.5, "quantized": 0.5}).save(tmp_path / "design")
    monkeypatch.setattr(Design, "_figures", lambda self, out: None)  # the finished design's plots: not compared
    kw = dict(minutes=5, max_steps=2, crop=64, sampling=1, val_images=1, val_every=2, batch=1, progress=False)
    want = doefab.finetune_end_to_end(tmp_path / "design", tmp_path / "cpu", device="cpu", **kw)
    got = doefab.finetune_end_to_end(tmp_path / "design", tmp_path / "dev", device=device, **kw)
    rows = [np.loadtxt(tmp_path / d / "history.csv", delimiter=",", skiprows=1) for d in ("dev", "cpu")]
    agree(device, rows[0][:, [0, 2, 3]], rows[1][:, [0, 2, 3]], rtol=2e-3)  # step, loss, validation MAE
    assert got["metric"]["quantized"] == pytest.approx(want["metric"]["quantized"], abs=2e-2)
