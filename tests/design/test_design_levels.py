"""The number of levels is a property of a design: the optimiser's quantization-aware stage and the finished level map
follow it, design.json records it (an old record without it means 16), and ``doefab design --n-levels`` (or its earlier spelling ``--levels``) sets it."""

import json
import math

import numpy as np
import pytest
import torch

import doefab
from doefab.design.design import Design, levels_sha256
from doefab.design.optimize import coded_mask
from doefab.errors import DoefabError
from doefab.fabrication.levels import quantize_levels
from doefab.optics.psf import PSFPlan


@pytest.fixture(scope="module")
def eight(tiny_camera, tiny_streak):
    return doefab.optimize("streak", iterations=6, camera=tiny_camera, progress=False, task_params=tiny_streak,
                           n_levels=8, qat_fraction=0.5, eval_every=1)


def test_an_eight_level_design_is_quantized_to_eight_levels(eight, tiny_camera):
    cam = tiny_camera
    assert eight.n_levels == 8 and int(eight.levels.max()) <= 7
    coded = coded_mask(cam).numpy() > 0
    assert np.array_equal(eight.levels[coded], quantize_levels(eight.height, cam, 8)[coded])
    assert np.all(eight.levels[~coded] == 7)  # plain half and outside the aperture: unetched
    h2pi = 550e-9 / (float(cam.material.index(550e-9)) - 1)
    assert np.allclose(eight.quantized_height, eight.levels * h2pi / 8, rtol=1e-12, atol=0)
    # the quantized metric is the task's metric of the 8-level relief's PSF, not a 16-level one
    task = doefab.get_task("streak", **eight.task_params)
    task.bind(cam)
    plan = PSFPlan(cam, eight.wavelengths, eight.depths, task.kernel_size, halves=("coded",))
    with torch.no_grad():
        m8 = task.metric(plan(eight.levels * h2pi / 8).coded, cam)["value"]
        m16 = task.metric(plan(quantize_levels(eight.height, cam, 16) * h2pi / 16).coded, cam)["value"]
    assert eight.metrics["quantized"] == pytest.approx(m8, abs=1e-6)
    assert abs(m16 - m8) > 1e-4  # the check can tell 8 from 16 levels
    # the quantization-aware stage ran at 8 levels: its last full evaluation is the 8-level design's metric
    assert eight.history[-1][3] == pytest.approx(m8, abs=1e-5)
    assert eight.extra["config"]["n_levels"] == 8


def test_design_json_records_the_levels_and_an_old_record_means_sixteen(eight, tiny_camera, tmp_path):
    eight.save(tmp_path / "d8")
    meta = json.loads((tmp_path / "d8" / "design.json").read_text())
    h2pi = 550e-9 / (float(tiny_camera.material.index(550e-9)) - 1)
    assert meta["n_levels"] == 8 and meta["level_step_m"] == pytest.approx(h2pi / 8, rel=1e-12)
    back = Design.load(tmp_path / "d8")
    assert back.n_levels == 8 and np.array_equal(back.levels, eight.levels)
    # a 16-level design.json written before n_levels was a choice loads as 16 with its checksum unchanged
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    d16 = Design(task="streak", task_params=eight.task_params, camera=tiny_camera, wavelengths=eight.wavelengths,
                 depths=eight.depths, height=doefab.levels_to_height(lv, tiny_camera), levels=lv,
                 metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d16.save(tmp_path / "old")
    meta = json.loads((tmp_path / "old" / "design.json").read_text())
    del meta["n_levels"]
    (tmp_path / "old" / "design.json").write_text(json.dumps(meta))
    old = Design.load(tmp_path / "old")
    assert old.n_levels == 16 and levels_sha256(old.levels) == meta["levels_sha256"]
    assert old.quantized_height == pytest.approx(lv * h2pi / 16, rel=1e-12)


def test_level_counts_and_maps_that_disagree_are_refused(eight, tmp_path):
    kw = dict(task="streak", task_params={}, camera=eight.camera, wavelengths=(550e-9,), depths=(5.0,),
              height=eight.height, metrics={})
    with pytest.raises(DoefabError, match="Design.n_levels = 12"):
        Design(levels=eight.levels, n_levels=12, **kw)
    with pytest.raises(DoefabError, match="holds level 7 but the design has n_levels = 4"):
        Design(levels=eight.levels, n_levels=4, **kw)
    eight.save(tmp_path / "d")
    meta = json.loads((tmp_path / "d" / "design.json").read_text())
    meta.update(n_levels=4, level_step_m=meta["level_step_m"] * 2)  # consistent step, but the map holds level 7
    (tmp_path / "d" / "design.json").write_text(json.dumps(meta))
    with pytest.raises(DoefabError, match="levels 0..3"):
        Design.load(tmp_path / "d")


def test_design_command_passes_levels_to_the_optimiser(eight, tmp_path, monkeypatch, capsys):
    from doefab.cli import main

    seen = {}

    def fake_optimize(task, **kw):  # the preset camera's design takes minutes; the flag's plumbing is the test
        seen.update(kw)
        return eight

    monkeypatch.setattr(doefab, "optimize", fake_optimize)
    assert main(["design", "--task", "streak", "--n-levels", "8", "--iterations", "1", "--out", str(tmp_path / "d")]) == 0
    assert seen["n_levels"] == 8 and "8-level" in capsys.readouterr().out
    assert json.loads((tmp_path / "d" / "design.json").read_text())["n_levels"] == 8
    with pytest.raises(SystemExit) as exc:
        main(["design", "--task", "streak", "--n-levels", "12", "--out", str(tmp_path / "e")])
    assert exc.value.code == 2 and "--n-levels" in capsys.readouterr().err
    seen.clear()  # the earlier spelling sets the same count
    assert main(["design", "--task", "streak", "--levels", "8", "--iterations", "1", "--out", str(tmp_path / "f")]) == 0
    assert seen["n_levels"] == 8


@pytest.mark.parametrize("n_levels", [2, 4, 8, 32])
def test_n_level_blazed_grating_sends_sinc2_of_one_over_n_into_the_first_order(n_levels, tmp_path):
    """A continuous blaze of period 2N pixels, quantized by the design path to N levels (steps two pixels wide, so
    the staircase is exact), saved and loaded as a design: its first order holds sinc²(1/N) of the light
    (the staircase's Fourier coefficient), at the grating equation's angle. Measured as the first order's window
    energy over the blank half-aperture's."""
    cam = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=5.4e-6, doe_pixels=400, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    lam, k = cam.design_wavelength, 41
    h = doefab.blazed_grating_height(cam, 2 * n_levels)
    lv = quantize_levels(h, cam, n_levels)
    Design(task="grating", task_params={}, camera=cam, wavelengths=(lam,), depths=(5.0,), height=h, levels=lv,
           n_levels=n_levels, metrics={}).save(tmp_path / "d")
    d = Design.load(tmp_path / "d")
    u1 = cam.sensor_distance * math.tan(math.asin(lam / (2 * n_levels * cam.doe_pitch)))
    kw = dict(kernel_size=k, halves=("coded",), precision="float64")
    spot = doefab.split_aperture_psf(d.quantized_height, cam, [lam], [5.0], center=(u1, 0.0), **kw).coded[0, 0]
    blank = doefab.split_aperture_psf(None, cam, [lam], [5.0], **kw).coded[0, 0]
    eff = float(spot.sum() / blank.sum())
    # 5e-4 separates N = 32 (0.99679) from N = 16 (0.98721)
    assert eff == pytest.approx(np.sinc(1 / n_levels) ** 2, abs=5e-4)
    c = np.arange(k) - k // 2
    assert abs(float((spot.numpy().sum(0) * c).sum() / spot.numpy().sum())) < 0.1


def test_the_networks_see_the_psf_of_the_designs_own_levels_in_its_own_window(eight, tiny_camera, tmp_path):
    """A non-16-level design's networks are told the PSF of its 8-level relief (level · λ/(n−1)/8, computed
    here from the substrate's index), in a window no smaller than the one it was optimised in."""
    from doefab.reconstruction.specs import get_spec, network_kernel, psf_pair

    d = tmp_path / "d8"
    task = doefab.get_task("streak", **eight.task_params)
    task.bind(tiny_camera)
    big = dict(eight.task_params, kernel_size=get_spec("hdr").kernel + 20)  # optimised in a larger window
    Design(**{**eight.__dict__, "task_params": big}).save(d)
    pair, sha = psf_pair("hdr", d)
    assert sha == levels_sha256(eight.levels)
    k = pair.coded.shape[-1]
    assert k == network_kernel("hdr", big["kernel_size"]) == get_spec("hdr").kernel + 20  # not cut off
    h2pi = 550e-9 / (float(tiny_camera.material.index(550e-9)) - 1)
    plan = PSFPlan(tiny_camera, eight.wavelengths, eight.depths, k)
    with torch.no_grad():
        want8 = plan(eight.levels * h2pi / 8)
        as16 = plan(eight.levels * h2pi / 16)  # the level map read as if it had 16 levels
    assert torch.allclose(pair.coded, want8.coded, atol=1e-7, rtol=1e-5)
    assert not torch.allclose(pair.coded, as16.coded, atol=1e-5, rtol=1e-3)


@pytest.mark.parametrize("bands", [(550e-9,), (486e-9, 589e-9, 656e-9), (656e-9, 486e-9, 589e-9),
                                   (656e-9, 589e-9, 486e-9, 450e-9)])
def test_an_rgb_network_refuses_a_design_whose_bands_are_not_red_green_blue(eight, tmp_path, monkeypatch, bands):
    """The HDR network's scenes are the camera's RGB: a design on one band, on three not listed longest first (a
    486 nm PSF would blur the red or green channel), or on four is refused by name, by ``psf_pair`` (train,
    evaluate, the network judge) and by ``train --design`` before its output folder is made; the same levels on
    red, green, blue are taken."""
    from doefab.reconstruction.specs import psf_pair

    d = tmp_path / "bands"
    Design(**{**eight.__dict__, "wavelengths": bands, "psf_quantized": None, "targets": None}).save(d)
    with pytest.raises(DoefabError) as exc:
        psf_pair("hdr", d)
    got = ", ".join(f"{w * 1e9:g}" for w in bands)
    assert "three bands" in str(exc.value) and "longest first" in str(exc.value) and f"got [{got}]" in str(exc.value)
    import doefab.tolerance.conditions as conditions
    from doefab.cli import main

    def no_work(*a, **k):
        raise AssertionError("the fabricated parts' PSFs were computed before the design was refused")

    monkeypatch.setattr(conditions, "for_splits", no_work)  # an internal error (exit 1) if reached
    out = tmp_path / "net"
    assert main(["train", "--task", "hdr", "--design", str(d), "--minutes", "0.05", "--out", str(out)]) == 2
    assert not out.exists()
    ok = tmp_path / "rgb"
    rgb = (630e-9, 532e-9, 450e-9)
    Design(**{**eight.__dict__, "wavelengths": rgb, "psf_quantized": None, "targets": None}).save(ok)
    assert tuple(psf_pair("hdr", ok)[0].wavelengths) == rgb
