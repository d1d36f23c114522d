"""``--psf FILE`` of ``doefab evaluate`` and ``doefab finetune``: the networks are told the pair in the file, the
file is recorded, a pair the networks cannot take is refused before any output, and the network-only fine-tune
writes weights the loader and ``evaluate --psf`` read."""

import functools
import hashlib
import json

import pytest
import torch

from doefab.cli import main
from doefab.optics.psf import PSFPair
from doefab.optics.psffile import save_psf_pair

TINY = {"features": 1, "width": 4, "highlight_iters": 5, "bound_iters": 4, "bound_rounds": 2}
EVAL = ["evaluate", "--task", "hdr", "--variants", "proposed", "--images", "1", "--size", "64", "--split", "val"]


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A tiny HDR network of the committed design; its nominal pair, the pair without coded light and a one-band
    pair, as psf_pair.npz files."""
    from doefab.reconstruction.specs import psf_pair
    from doefab.reconstruction.train import train

    root = tmp_path_factory.mktemp("psfarg")
    train("hdr", "proposed", minutes=1, out_dir=root / "t", weights_dir=root / "w", crop=64, val_images=1,
          val_every=100, arch=TINY, progress=False, max_steps=1)
    p = psf_pair("hdr")[0]
    save_psf_pair(p, root / "nominal.npz", {"source": "simulation"})
    save_psf_pair(PSFPair(torch.zeros_like(p.coded), p.uncoded, p.wavelengths, p.depths, p.sensor_pitch),
                  root / "dark.npz", {"source": "calibrate", "recordings_sha256": "ab" * 32})
    save_psf_pair(PSFPair(p.coded[:, :1], p.uncoded[:, :1], p.wavelengths[:1], p.depths, p.sensor_pitch),
                  root / "one_band.npz", {"source": "calibrate"})
    return root


def _evaluate(weights, out, *flags) -> dict:
    assert main([*EVAL, "--weights-dir", str(weights), *flags, "--out", str(out)]) == 0
    return json.loads((out / "metrics.json").read_text())


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_evaluate_tells_the_network_the_pair_and_records_the_file(lab, tmp_path):
    """The same captures (through the nominal pair, --capture-psf): told the file's nominal pair the network scores
    exactly what it scores told nothing; told a pair without coded light, something else."""
    nominal, dark = lab / "nominal.npz", lab / "dark.npz"
    plain = _evaluate(lab / "w", tmp_path / "a", "--capture-psf", str(nominal), "--clean")
    same = _evaluate(lab / "w", tmp_path / "b", "--psf", str(nominal), "--clean")
    other = _evaluate(lab / "w", tmp_path / "c", "--psf", str(dark), "--capture-psf", str(nominal), "--clean")
    psnr = {k: r["rows"]["proposed"]["psnr"] for k, r in (("plain", plain), ("same", same), ("other", other))}
    assert psnr["same"] == pytest.approx(psnr["plain"], abs=1e-9) and abs(psnr["other"] - psnr["plain"]) > 1.0
    assert plain["psf"]["told"] == "the design's nominal pair"
    told, through = other["psf"]["told"], other["psf"]["captured_through"]
    assert told["sha256"] == _sha(dark) and told["provenance"] == {"source": "calibrate",
                                                                    "recordings_sha256": "ab" * 32}
    assert through["sha256"] == _sha(nominal) and through["provenance"] == {"source": "simulation"}
    assert same["psf"]["captured_through"]["sha256"] == _sha(nominal)  # --psf alone: captured through it too


@pytest.mark.parametrize("cmd", [["evaluate", "--task", "hdr"], ["finetune", "--task", "hdr"]])
def test_a_pair_of_other_bands_is_refused_with_the_fix(cmd, lab, one_clear_error):
    line = one_clear_error(lambda f, t: [*cmd, "--psf", lab / "one_band.npz", "--out", t / "o"], 2,
                           "--psf: the PSF pair is for 1 band")
    assert "(the network: 3 bands" in line and "psf_pair_fitted.npz" in line


@pytest.mark.parametrize("args, needle", [
    (["finetune", "--psf", "p.npz"], "--psf needs --task"),
    (["finetune", "--psf", "p.npz", "--task", "hdr", "--doe-every", "2"], "--doe-every moves the DOE"),
    (["finetune", "--task", "hdr"], "--task is for a network-only fine-tune on a PSF pair"),
    (["finetune"], "give --design"),
    (["evaluate", "--task", "hdr", "--psf", "missing.npz"], "--psf: "),
    (["evaluate", "--task", "hdr", "--crosstalk", "c.json"], "--crosstalk is the measured camera's: give its part"),
    (["finetune", "--design", "d", "--crosstalk", "c.json"], "--crosstalk is for a network-only fine-tune")])
def test_what_the_flags_cannot_do_is_refused_before_any_output(args, needle, one_clear_error):
    one_clear_error(lambda f, t: [*args, "--out", t / "o"], 2, needle)


def test_finetune_psf_writes_weights_that_evaluate_reads_and_resumes(lab, tmp_path, monkeypatch):
    import doefab.reconstruction.partfinetune as pft
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.specs import design_dir

    monkeypatch.setattr(pft, "finetune_on_pair", functools.partial(pft.finetune_on_pair, crop=64, val_images=1,
                                                                   batch=1, val_every=1, progress=False))
    design = {f.name: _sha(f) for f in design_dir("hdr").iterdir()}
    out, psf = tmp_path / "ft", str(lab / "nominal.npz")
    argv = ["finetune", "--task", "hdr", "--psf", psf, "--weights-dir", str(lab / "w"), "--clean", "--steps", "1",
            "--out", str(out)]
    assert main(argv) == 0
    rec = load_reconstructor("hdr", weights_dir=out / "weights")
    assert rec.meta["training"]["fine_tune"]["told"]["sha256"] == _sha(lab / "nominal.npz")
    assert {f.name: _sha(f) for f in design_dir("hdr").iterdir()} == design and not (out / "design").exists()
    assert main(argv[:-4] + ["--steps", "2", "--resume", "--out", str(out)]) == 0
    again = load_reconstructor("hdr", weights_dir=out / "weights")
    assert again.meta["training"]["steps"] == 2
    got = _evaluate(out / "weights", tmp_path / "e", "--psf", psf)  # with the camera's crosstalk
    assert got["conditions"]["name"] == "measured" and got["psf"]["told"]["sha256"] == _sha(lab / "nominal.npz")
    assert got["weights"]["proposed"]["sha256"] == again.meta["weights_sha256"] != _sha(lab / "w" / "hdr_proposed.pt")


def test_evaluate_with_the_cameras_measured_crosstalk_mixes_the_views_by_the_file(lab, tmp_path):
    """--crosstalk: the views are mixed and unmixed by the file's ratios (recorded as measured, with the file's
    digest), which is not what the budget's sensor does; a file that is not a calibration is one clear error."""
    import numpy as np

    from doefab.imaging.crosstalkfile import save_crosstalk

    w = 400
    save_crosstalk(tmp_path / "xt.json", np.full(w, 0.2), np.full(w, 0.15), np.full(w, 1e-4), np.full(w, 1e-4))
    nominal = str(lab / "nominal.npz")
    budget = _evaluate(lab / "w", tmp_path / "a", "--psf", nominal)
    mine = _evaluate(lab / "w", tmp_path / "b", "--psf", nominal, "--crosstalk", str(tmp_path / "xt.json"))
    assert mine["conditions"]["crosstalk_source"] == "measured" and "crosstalk_source" not in budget["conditions"]
    assert mine["rows"]["proposed"]["psnr"] != budget["rows"]["proposed"]["psnr"]
    (tmp_path / "bad.json").write_text("{}")
    assert main([*EVAL, "--weights-dir", str(lab / "w"), "--psf", nominal, "--crosstalk", str(tmp_path / "bad.json"),
                 "--out", str(tmp_path / "c")]) == 2
    assert not (tmp_path / "c").exists()
