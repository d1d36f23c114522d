"""``doefab reconstruct``: a user's own 16-bit captures in, files other programs open out; every unusable input
refused with one line (exit 2) before anything is written."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import doefab
from doefab.cli import main
from doefab.lab.frames import write_frame
from doefab.reconstruction.illuminant import illuminant_names


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    """Two exposures of 96×128 px as a camera delivers them: depth scenes through the shipped depth network's
    PSFs, mixed by per-column crosstalk, 16-bit colour TIFFs (coded and plain views in two folders), the
    crosstalk.json of that camera and the network's own PSF pair as psf_pair.npz."""
    from doefab.imaging.crosstalk import mix_crosstalk, save_crosstalk
    from doefab.reconstruction import data

    root = tmp_path_factory.mktemp("shots")
    rec = doefab.load_reconstructor("depth")
    a, b = np.linspace(0.03, 0.07, 128), np.linspace(0.06, 0.04, 128)
    for i in range(2):
        scene, dm = data.depth_sample(np.random.default_rng(i), 128, "val")
        c, u = doefab.simulate_captures(scene[:, :96], rec.pair, depth_map=dm[:96], seed=i, noise="none")
        left, right = mix_crosstalk(np.asarray(u), np.asarray(c), a, b)  # the plain view is the left one
        write_frame(root / "coded" / f"shot{i}.tiff", np.moveaxis(np.clip(right, 0, 1), 0, -1) * 65535)
        write_frame(root / "plain" / f"shot{i}_L.tiff", np.moveaxis(np.clip(left, 0, 1), 0, -1) * 65535)
        np.save(root / f"clean{i}.npy", np.stack([np.asarray(c), np.asarray(u)]))  # the views before the crosstalk
    save_crosstalk(root / "crosstalk.json", a, b, np.full(128, 1e-4), np.full(128, 1e-4), {"source": "test"})
    rec.pair.save(root / "psf_pair.npz", {"source": "simulation"})
    return root


def test_depth_pairs_reconstructed_with_psf_and_crosstalk(shots, tmp_path, capsys):
    import tifffile

    from doefab.imaging.crosstalk import DualPixelCrosstalk
    from doefab.lab.reconstruct import load_views, reconstruct_tiled

    out = tmp_path / "out"
    rc = main(["reconstruct", "--task", "depth", "--coded", str(shots / "coded" / "*.tiff"), "--uncoded",
               str(shots / "plain" / "*.tiff"), "--psf", str(shots / "psf_pair.npz"), "--crosstalk",
               str(shots / "crosstalk.json"), "--tile", "64", "--overlap", "32", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    names = {p.name for p in out.iterdir()}
    for stem in ("shot0", "shot1"):
        assert {f"{stem}.depth_m.tiff", f"{stem}.depth_mm.png", f"{stem}.png"} <= names
    record = json.loads((out / "reconstruct.json").read_text())
    first = record["pairs"][0]
    assert first["coded"].endswith("shot0.tiff") and first["uncoded"].endswith("shot0_L.tiff")
    import hashlib

    assert first["coded_sha256"] == hashlib.sha256((shots / "coded" / "shot0.tiff").read_bytes()).hexdigest()
    assert record["tile_px"] == 64 and record["overlap_px"] == 32
    assert record["psf"]["provenance"]["source"] == "simulation"
    assert record["crosstalk"]["sha256"] and record["versions"]["OpenEXR"] and record["weights"]["sha256"]
    # the file holds what the API gives for the unmixed views
    rec = doefab.load_reconstructor("depth")
    cam = DualPixelCrosstalk.load(shots / "crosstalk.json")
    coded, uncoded = load_views(shots / "coded" / "shot0.tiff", shots / "plain" / "shot0_L.tiff", cam)
    want = reconstruct_tiled(rec, coded, uncoded, 64, 32, psf=doefab.PSFPair.load(shots / "psf_pair.npz"))
    got = tifffile.imread(out / "shot0.depth_m.tiff")
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
    # the crosstalk was undone: the unmixed coded view is not the recorded one
    from doefab.lab.reconstruct import read_capture

    assert np.abs(read_capture(shots / "coded" / "shot0.tiff") - coded).max() > 1e-3
    # ... to the views before it, within the 16-bit files' rounding
    clean = np.load(shots / "clean0.npy")
    np.testing.assert_allclose(np.asarray(coded), clean[0], rtol=0, atol=1e-4)
    np.testing.assert_allclose(np.asarray(uncoded), clean[1], rtol=0, atol=1e-4)


@pytest.mark.parametrize("task, files", [("hdr", ["x.exr", "x.png"]), ("hyperspectral", ["x.hdr", "x.img", "x.png"])])
def test_hdr_and_spectra_write_their_formats(task, files, tmp_path, capsys):
    rng = np.random.default_rng(0)
    for name in ("c/x.tiff", "u/x.tiff"):
        write_frame(tmp_path / name, rng.uniform(0, 65535, (96, 128, 3)))
    rc = main(["reconstruct", "--task", task, "--coded", str(tmp_path / "c/x.tiff"), "--uncoded",
               str(tmp_path / "u/x.tiff"), "--out", str(tmp_path / "o")])  # 96×128 px: one tile
    err = capsys.readouterr().err
    assert rc == 0, err
    assert set(files) | {"reconstruct.json", ".doefab-output.json"} == {p.name for p in (tmp_path / "o").iterdir()}
    first = json.loads((tmp_path / "o" / "reconstruct.json").read_text())
    assert first["torch_threads"] == torch.get_num_threads()
    pair = first["pairs"][0]
    if task == "hyperspectral":  # the light the spectra were formed under, and a frame under the 191 px window
        assert set(pair["light"]) <= set(illuminant_names()) and sum(pair["light"].values()) == pytest.approx(1, 0.05)
        assert "x.tiff: the frame is 128×96 px, under the 191 px PSF window" in err and pair["warnings"]
    else:  # 96 px holds the HDR network's 95 px window
        assert "light" not in pair and pair["warnings"] == [] and "warning" not in err
    # replaced (--force) by another capture's results: the earlier run's go, the folder holds what its record says
    for name in ("c/y.tiff", "u/y.tiff"):
        write_frame(tmp_path / name, rng.uniform(0, 65535, (96, 128, 3)))
    rc = main(["reconstruct", "--task", task, "--coded", str(tmp_path / "c/y.tiff"), "--uncoded",
               str(tmp_path / "u/y.tiff"), "--out", str(tmp_path / "o"), "--force"])
    assert rc == 0, capsys.readouterr().err
    want = {f.replace("x.", "y.") for f in files} | {"reconstruct.json", ".doefab-output.json"}
    assert want == {p.name for p in (tmp_path / "o").iterdir()}
    record = json.loads((tmp_path / "o" / "reconstruct.json").read_text())
    assert [f for pair in record["pairs"] for f in pair["files"]] == [f.replace("x.", "y.") for f in files]


def _pair(work, size=(96, 128), channels=3, name="x"):
    shape = (*size, channels) if channels == 3 else size
    for folder in ("c", "u"):
        write_frame(work / folder / f"{name}.tiff", np.full(shape, 30000.0))
    return ["--coded", work / "c" / f"{name}.tiff", "--uncoded", work / "u" / f"{name}.tiff"]


def _two_sizes(work):
    args = _pair(work)
    write_frame(work / "u" / "x.tiff", np.full((96, 96, 3), 30000.0))
    return args


def test_captures_clipped_in_both_views_are_warned_of(tmp_path, capsys):
    """A fifth of the frame at full scale in both views: neither view measures the scene there, and the warning says
    so with its share; one view clipped alone (the HDR design's case) or under 1 % of the pixels clipped in both is
    not warned of."""
    from doefab.lab.capturenotes import clipped_note

    rng = np.random.default_rng(1)
    coded, plain = rng.uniform(0, 30000, (96, 128, 3)), rng.uniform(0, 30000, (96, 128, 3))
    coded[:, :26], plain[:, :26] = 65535, 65535  # 26 of 128 columns: 20.3 % of the pixels
    write_frame(tmp_path / "c/x.tiff", coded)
    write_frame(tmp_path / "u/x.tiff", plain)
    rc = main(["reconstruct", "--task", "hdr", "--coded", str(tmp_path / "c/x.tiff"), "--uncoded",
               str(tmp_path / "u/x.tiff"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "x.tiff: 20.3% of the pixels clip in both captures" in err
    assert json.loads((tmp_path / "o" / "reconstruct.json").read_text())["pairs"][0]["warnings"]
    one = np.zeros((3, 8, 8))
    assert clipped_note(np.ones((3, 8, 8)), one) is None and "100.0%" in clipped_note(np.ones((3, 8, 8)), one + 1)
    few, more = np.zeros((3, 100, 100)), np.zeros((3, 100, 100))
    few[1, :1] = more[1, :2] = 1.0  # one row (1 % of the pixels, in one channel), two rows (2 %)
    assert clipped_note(few, few) is None and "2.0% of the pixels" in clipped_note(more, more)


def test_views_that_break_the_split_apertures_identity_less_swapped_are_warned_of():
    """Views of one scene through two PSFs obey coded ⊛ PSF_plain = plain ⊛ PSF_coded in the valid region, to
    rounding; given the other way round they do not, and the note names the swap. Random PSFs at one plane and a
    random scene: the identity is the convolution's commutativity, computed here by direct summation."""
    from scipy.signal import convolve2d

    from doefab.lab.capturenotes import looks_swapped, swapped_note, view_mismatch
    from doefab.optics.psf import PSFPair

    rng = np.random.default_rng(3)
    k, n = 9, 120
    pc, pu = rng.uniform(0, 1, (1, 3, k, k)), rng.uniform(0, 1, (1, 3, k, k))
    pc[..., k // 2, :] += 5.0  # a streak across the coded half's window, a spot on the plain half's
    pu[..., k // 2, k // 2] += 20.0
    pc, pu = (0.5 * p / p.sum(axis=(-1, -2), keepdims=True) for p in (pc, pu))
    scene = rng.uniform(0, 1, (3, n + k - 1, n + k - 1))
    views = [np.stack([convolve2d(scene[c], p[0, c], mode="valid") for c in range(3)]) for p in (pc, pu)]
    stated, swapped = view_mismatch(views[0], views[1], pc, pu)
    assert stated < 1e-12 and swapped > 0.01
    assert view_mismatch(views[0] * 0.8, views[1], pc, pu)[0] < 1e-12  # a view's gain changes nothing
    pair = PSFPair(torch.from_numpy(pc), torch.from_numpy(pu), (656e-9, 589e-9, 486e-9), (5.0,), 5.4e-6)
    assert swapped_note(views[0], views[1], pair) is None
    assert "look swapped" in swapped_note(views[1], views[0], pair)
    assert np.isnan(view_mismatch(views[1][:, :k, :k], views[0][:, :k, :k], pc, pu)).all()  # no wider than K
    holed = [v.copy() for v in views]
    holed[1][1, 60, 60] = np.nan  # a dead pixel leaves out the windows that hold it, not the whole frame
    assert "look swapped" in swapped_note(holed[1], holed[0], pair) and np.isnan(holed[1][1, 60, 60])
    flat = [np.full_like(v, 0.3) for v in views]  # nothing to tell by
    assert np.isnan(view_mismatch(flat[0], flat[1], pc, pu)).all() and swapped_note(flat[1], flat[0], pair) is None
    assert looks_swapped(0.6, 0.1) and not looks_swapped(0.004, 0.001) and not looks_swapped(np.nan, 0.0)


def test_swapped_captures_are_warned_of_by_reconstruct(tmp_path, capsys):
    """An HDR scene's two views through the shipped network's PSFs, written as 16-bit TIFFs: given as recorded,
    nothing is said; given swapped, the warning names it, on the terminal and in reconstruct.json."""
    from doefab.reconstruction import data

    rec = doefab.load_reconstructor("hdr")
    scene = data.hdr_sample(np.random.default_rng(5), 192, "val")
    c, u = doefab.simulate_captures(scene, rec.pair, seed=5, noise="none")
    write_frame(tmp_path / "c/x.tiff", np.moveaxis(np.clip(np.asarray(c), 0, 1), 0, -1) * 65535)
    write_frame(tmp_path / "u/x.tiff", np.moveaxis(np.clip(np.asarray(u), 0, 1), 0, -1) * 65535)
    for order, warned in ((("c", "u"), False), (("u", "c"), True)):
        out = tmp_path / ("o" + "".join(order))
        rc = main(["reconstruct", "--task", "hdr", "--coded", str(tmp_path / order[0] / "x.tiff"), "--uncoded",
                   str(tmp_path / order[1] / "x.tiff"), "--out", str(out)])
        err = capsys.readouterr().err
        assert rc == 0, err
        assert ("captures look swapped" in err) == warned, err
        notes = json.loads((out / "reconstruct.json").read_text())["pairs"][0]["warnings"]
        assert any("look swapped" in n for n in notes) == warned


@pytest.mark.parametrize("build, needle", [
    (lambda w: ["--coded", w / "*.tiff", "--uncoded", w / "*.png"] if _pair(w) else [], "no file matches"),
    (lambda w: _pair(w) + ["--coded", w / "c" / "x.tiff", w / "u" / "x.tiff"], "--coded matches 2 files and"),
    (lambda w: _two_sizes(w), "u/x.tiff is 96×96 px: pair the two views"),
    (lambda w: _pair(w, channels=1), "x.tiff is a monochrome frame (128×96 px)"),
    (lambda w: _pair(w, size=(48, 128)), "are 128×48 px: the networks need at least 64 px on each side"),
    (lambda w: _pair(w) + ["--tile", "128"], "more than half the tile (128 px): give a tile of at least 192 px"),
    (lambda w: _pair(w) + ["--tile", "80", "--overlap", "32"], "tile 80 must be a multiple of 32"),
    (lambda w: _pair(w) + ["--overlap", "32", "--black-level", "70000"], "below the white level 65535 DN"),
])
def test_unusable_captures_are_one_clear_error_and_nothing_is_written(build, needle, one_clear_error):
    one_clear_error(lambda f, w: ["reconstruct", "--task", "depth", *build(w), "--out", w / "o"], 2, needle)


def test_a_crosstalk_of_another_width_is_refused(one_clear_error, tmp_path):
    from doefab.imaging.crosstalk import save_crosstalk

    save_crosstalk(tmp_path / "ct.json", *(np.full(100, v) for v in (0.05, 0.05, 1e-4, 1e-4)))
    one_clear_error(lambda f, w: ["reconstruct", "--task", "depth", *_pair(w), "--overlap", "32", "--crosstalk",
                                  tmp_path / "ct.json", "--out", w / "o"], 2,
                    "holds 100 columns but")


def test_a_psf_of_other_bands_is_refused_with_the_fitted_pair_as_the_fix(shots, one_clear_error, tmp_path):
    from doefab.optics.psf import PSFPair

    pair = doefab.PSFPair.load(shots / "psf_pair.npz")
    one_band = PSFPair(pair.coded[:, :1], pair.uncoded[:, :1], pair.wavelengths[:1], pair.depths, pair.sensor_pitch)
    one_band.save(tmp_path / "one_band.npz")
    one_clear_error(lambda f, w: ["reconstruct", "--task", "depth", *_pair(w), "--psf", tmp_path / "one_band.npz",
                                  "--out", w / "o"], 2, "psf_pair_fitted.npz")
