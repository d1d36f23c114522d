"""Training writes weights + metadata; load_reconstructor verifies them (tiny network, seconds)."""

import json
import re

import numpy as np
import pytest
import torch

import doefab
from doefab.errors import DoefabError
from doefab.reconstruction.train import train


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    root = tmp_path_factory.mktemp("w")
    meta = train("hdr", "proposed", minutes=0.03, out_dir=root / "run", weights_dir=root / "weights", crop=64,
                 val_images=2, val_every=2,
                 arch={"features": 1, "width": 4, "highlight_iters": 5, "bound_iters": 4, "bound_rounds": 2},
                 progress=False)
    return root, meta


def test_training_writes_weights_history_and_a_complete_record(weights):
    root, meta = weights
    assert meta["training"]["steps"] >= 1 and meta["design"] == "streak"
    assert (root / "weights" / "hdr_proposed.pt").is_file()
    rec = json.loads((root / "weights" / "hdr_proposed.json").read_text())
    for key in ("design_levels_sha256", "psf", "training", "validation", "weights_sha256", "arch"):
        assert key in rec
    assert (root / "run" / "history.csv").read_text().startswith("step,wall_time_s,loss,val_psnr")


def test_loaded_network_runs_on_any_multiple_of_32(weights):
    root, _ = weights
    rec = doefab.load_reconstructor("hdr", weights_dir=root / "weights")
    assert rec.design_sha256 == rec.meta["design_levels_sha256"] and rec.pair.coded.shape[1] == 3
    for h, w in ((64, 64), (96, 128)):
        out = rec(np.random.rand(3, h, w).astype(np.float32), np.random.rand(3, h, w).astype(np.float32))
        assert out.shape == (3, h, w) and np.all(out >= 0)
    # a swapped-in PSF pair changes the output (the PSF is an input)
    c, u = torch.rand(3, 64, 64), torch.rand(3, 64, 64)
    other = rec.pair.coded.flip(-1)
    assert not torch.allclose(rec(c, u), rec(c, u, psf=other))
    with pytest.raises(DoefabError, match="multiples of 32"):
        rec(np.zeros((3, 60, 64)), np.zeros((3, 60, 64)))
    with pytest.raises(DoefabError, match="NaN"):
        rec(np.full((3, 64, 64), np.nan), np.zeros((3, 64, 64)))


def test_tampered_or_mismatched_weights_are_refused(weights, tmp_path):
    root, _ = weights
    import shutil

    w = tmp_path / "w"
    shutil.copytree(root / "weights", w)
    data = bytearray((w / "hdr_proposed.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (w / "hdr_proposed.pt").write_bytes(bytes(data))
    with pytest.raises(DoefabError, match="SHA-256 .* doefab train --task hdr --variant proposed"):
        doefab.load_reconstructor("hdr", weights_dir=w)
    shutil.copy(root / "weights" / "hdr_proposed.pt", w / "hdr_proposed.pt")
    meta = json.loads((w / "hdr_proposed.json").read_text())
    meta["design_levels_sha256"] = "0" * 64
    (w / "hdr_proposed.json").write_text(json.dumps(meta))
    with pytest.raises(DoefabError, match="another design"):
        doefab.load_reconstructor("hdr", weights_dir=w)
    with pytest.raises(DoefabError, match="no weights"):
        doefab.load_reconstructor("hdr", "coded_only", weights_dir=w)


def test_resume_is_exact(tmp_path):
    # a constant rate: the cosine schedule follows wall time, which no two runs share to the bit
    kw = dict(minutes=5, crop=64, val_images=1, val_every=100, arch={"features": 1, "width": 4}, progress=False,
              schedule="constant")
    train("hdr", "proposed", out_dir=tmp_path / "a", weights_dir=tmp_path / "wa", max_steps=4, **kw)
    train("hdr", "proposed", out_dir=tmp_path / "b", weights_dir=tmp_path / "wb", max_steps=2, **kw)
    train("hdr", "proposed", out_dir=tmp_path / "b", weights_dir=tmp_path / "wb", max_steps=4, resume=True, **kw)
    a = torch.load(tmp_path / "wa" / "hdr_proposed.pt", weights_only=True)
    b = torch.load(tmp_path / "wb" / "hdr_proposed.pt", weights_only=True)
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_depth_network_takes_its_cost_volume_psfs_and_a_swapped_pair(tmp_path):
    from types import SimpleNamespace

    meta = train("depth", "proposed", minutes=5, out_dir=tmp_path / "run", weights_dir=tmp_path / "w", crop=64,
                 val_images=1, val_every=100, max_steps=1, arch={"width": 4, "cost_volume": True}, progress=False)
    assert meta["arch"]["cost_volume"] is True
    rec = doefab.load_reconstructor("depth", weights_dir=tmp_path / "w")
    c, u = torch.rand(3, 64, 64), torch.rand(3, 64, 64)
    d = rec(c, u)
    assert d.shape == (64, 64) and torch.equal(d, rec(c, u, psf=rec.pair))  # default = its own pair
    p = rec.pair
    swapped = SimpleNamespace(coded=p.uncoded, uncoded=p.coded, depths=p.depths, wavelengths=p.wavelengths)
    assert not torch.allclose(d, rec(c, u, psf=swapped))  # the cost volume reads the PSFs it is given
    for n in (1, 3):  # fewer planes than the network's: one clear error, not a broadcasting failure
        other = SimpleNamespace(coded=p.coded[:n], uncoded=p.uncoded[:n], depths=p.depths[:n],
                                wavelengths=p.wavelengths)
        with pytest.raises(DoefabError, match="depth planes"):
            rec(c, u, psf=other)
    with pytest.raises(DoefabError, match="both halves"):
        rec(c, u, psf=p.coded)


def test_networks_trained_for_another_camera_carry_its_response_and_are_refused_for_the_default(tmp_path,
                                                                                                 monkeypatch):
    """A hyperspectral network trained for the Nikon D5100: its training and evaluation captures are formed with
    that camera's curves (read here from colour-science's NPL data, not through doefab) and noise, it builds its
    inverses on them, records its sensor, and is refused for the default camera's captures unless asked for."""
    import colour

    import doefab.reconstruction.evaluate as evaluate_mod
    import doefab.reconstruction.train as train_mod
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.loader import load_reconstructor

    seen = []

    def spy(real):
        def call(task, split, indices, size, pair, response=None, noise="default", **kw):
            seen.append((split, response, noise))
            return real(task, split, indices, size, pair, response, noise, **kw)
        return call

    monkeypatch.setattr(train_mod, "make_batch", spy(train_mod.make_batch))
    monkeypatch.setattr(evaluate_mod, "make_batch", spy(evaluate_mod.make_batch))
    nikon = Sensor("Nikon D5100", full_well_e=8000.0, read_noise_e=2.0)
    meta = train("hyperspectral", "proposed", minutes=5, out_dir=tmp_path / "run", weights_dir=tmp_path / "w",
                 crop=64, val_images=1, val_every=1000, progress=False, max_steps=1, sensor=nikon,
                 arch={"features": 1, "width": 4, "illuminant_search": True, "illuminant_mix": True})
    assert meta["sensor"]["response"] == "Nikon D5100" and meta["sensor"]["full_well_e"] == 8000.0
    rec = load_reconstructor("hyperspectral", "proposed", tmp_path / "w", sensor=nikon)
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    bands_nm = np.asarray(rec.pair.wavelengths) * 1e9
    t = np.stack([np.interp(bands_nm, msds.wavelengths, msds.values[:, k]) for k in range(3)])
    assert np.allclose(rec.model.response.cpu().numpy(), t / t.sum(axis=1).max(), atol=1e-6)
    evaluate_mod.evaluate("hyperspectral", tmp_path / "ev", images=1, size=64, weights_dir=tmp_path / "w",
                          progress=False, variants=("proposed",), split="val", sensor=nikon)
    assert {split for split, _, _ in seen} == {"train", "val"} and len(seen) >= 3  # val, a step, the evaluation
    for _, response, noise in seen:
        assert np.allclose(response, t / t.sum(axis=1).max(), atol=1e-6)
        assert (noise.full_well_e, noise.read_noise_e) == (8000.0, 2.0)
    with pytest.raises(DoefabError, match="another sensor.*response Nikon D5100"):
        load_reconstructor("hyperspectral", "proposed", tmp_path / "w", sensor=Sensor())
    with pytest.raises(DoefabError, match="full_well_e 8000"):
        load_reconstructor("hyperspectral", "proposed", tmp_path / "w", sensor=Sensor("Nikon D5100"))
    anyway = load_reconstructor("hyperspectral", "proposed", tmp_path / "w", other_design=True, sensor=Sensor())
    assert anyway.meta["other_sensor"] and not np.allclose(anyway.model.response.cpu().numpy(),
                                                           Sensor().rgb(rec.pair.wavelengths))


def test_captures_of_other_bands_or_another_camera_are_refused_without_psf(weights):
    """A network reads captures through its own PSF pair: captures simulated through a pair of other bands or
    another camera are refused (one error naming what differs and ``psf=``) unless the caller gives ``psf=``;
    its own pair, a part of its design on its camera and a real camera's plain arrays are taken."""
    import dataclasses

    root, _ = weights
    rec = doefab.load_reconstructor("hdr", weights_dir=root / "weights")
    pair = rec.pair
    assert pair.camera == doefab.Camera.preset("hdr")  # the pair knows its camera
    scene = np.full((3, 64, 64), 0.5, np.float32)
    own = doefab.simulate_captures(scene, pair, noise="none")
    rec(*own)
    part = dataclasses.replace(pair, coded=pair.coded.roll(2, dims=-1))  # a misaligned part: same system
    rec(*doefab.simulate_captures(scene, part, noise="none"))
    other = dataclasses.replace(pair, camera=pair.camera.replace(sensor_pitch=4e-6))
    coded, uncoded = doefab.simulate_captures(scene, other, noise="none")
    with pytest.raises(DoefabError, match=r"^coded was simulated through a PSF pair of camera sensor_pitch 4e-06 m "
                                          r"\(the network: 5\.4e-06 m\).*simulate them through rec\.pair.*psf="):
        rec(coded, uncoded)
    assert np.array_equal(rec(coded, uncoded, psf=other), rec(np.asarray(coded), np.asarray(uncoded), psf=other))
    rec(np.asarray(coded), np.asarray(uncoded))  # plain arrays name no pair: a camera's captures
    with pytest.raises(DoefabError, match="sensor_pitch 4e-06 m"):
        rec(*doefab.simulate_captures(torch.from_numpy(scene), other, noise="none"))
    one = doefab.PSFPair(pair.coded[:, 1:2], pair.uncoded[:, 1:2], (550e-9,), pair.depths, pair.sensor_pitch,
                         camera=pair.camera)  # the README's old mistake: a 1-band 550 nm pair
    coded, uncoded = doefab.simulate_captures(scene[:1], one, response=np.full((3, 1), 0.3), noise="none")
    with pytest.raises(DoefabError, match=r"1 band 550 nm \(the network: 3 bands 656, 589, 486 nm\)"):
        rec(coded, uncoded)


def test_the_loader_never_suggests_overwriting_the_shipped_weights(tmp_path):
    from doefab.reconstruction.loader import _retrain

    hint = _retrain("depth", "proposed", None, tmp_path / "cand")
    assert "--weights-dir NEW_FOLDER" in hint and "--replace-shipped" not in hint
    assert _retrain("depth", "proposed", tmp_path / "w", None).endswith(f"--weights-dir {tmp_path / 'w'}")


def test_reconstructor_refuses_captures_outside_0_1():
    rec = doefab.load_reconstructor("hdr")
    rng = np.random.default_rng(0)
    coded, uncoded = rng.random((3, 64, 64)).astype(np.float32), rng.random((3, 64, 64)).astype(np.float32)
    with pytest.raises(DoefabError, match=r"captures are in \[0, 1\].*divide by the white level"):
        rec(coded * 255, uncoded * 255)
    with pytest.raises(DoefabError, match="integer .uint8. image.*255 for 8 bits"):
        rec((coded * 255).astype(np.uint8), (uncoded * 255).astype(np.uint8))
    with pytest.raises(DoefabError, match="subtract the black level"):
        rec(coded - 0.5, uncoded)


def test_the_weights_record_is_checked_against_a_design_before_any_psf(tmp_path, monkeypatch):
    """``weights_record`` refuses weights trained for another level map than the design folder's, and accepts the
    committed design's own shipped ones, without computing a PSF (``psf_pair`` is never called)."""
    import doefab.reconstruction.loader as loader
    from doefab.design.design import Design
    from doefab.reconstruction.specs import design_dir

    from doefab.optics.psf import PSFPlan

    def no_psfs(*args, **kwargs):
        raise AssertionError("weights_record computed PSFs")

    monkeypatch.setattr(loader, "psf_pair", no_psfs)
    monkeypatch.setattr(PSFPlan, "__call__", no_psfs)
    committed = design_dir("hdr")
    assert loader.weights_record("hdr", design=committed)["design_levels_sha256"] == \
        json.loads((committed / "design.json").read_text())["levels_sha256"]
    other = tmp_path / "other"
    d = Design.load(committed)
    d.levels[0, 0] = (int(d.levels[0, 0]) + 1) % d.n_levels  # another level map: the same camera and task
    d.save(other)
    with pytest.raises(DoefabError, match=re.escape(f"another design than {other}")):
        loader.weights_record("hdr", design=other)
    from doefab.imaging.sensor import Sensor

    with pytest.raises(DoefabError, match="another sensor"):  # the shipped network is the default sensor's
        loader.weights_record("hdr", design=committed, sensor=Sensor(read_noise_e=20.0))
    assert loader.weights_record("hdr", sensor=Sensor())["task"] == "hdr"  # None: the committed design


def test_an_unreadable_record_in_a_users_folder_names_moving_it_first(tmp_path, capsys):
    """Training never replaces a weights record it cannot read as its own, so the loader's fix for one says to
    move the files away before retraining; ``doefab train`` into that folder refuses exactly those files."""
    import shutil

    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.weights import WEIGHTS_DIR, foreign_weights_files

    shutil.copy(WEIGHTS_DIR / "hdr_uncoded_only.pt", tmp_path / "hdr_uncoded_only.pt")
    (tmp_path / "hdr_uncoded_only.json").write_text("{not json")
    with pytest.raises(DoefabError, match=r"not valid JSON \(training never replaces a record it cannot read: move "
                                          r"it and hdr_uncoded_only\.pt out of"):
        load_reconstructor("hdr", "uncoded_only", weights_dir=tmp_path)
    assert foreign_weights_files(tmp_path, "hdr", "uncoded_only")  # what train refuses to replace
