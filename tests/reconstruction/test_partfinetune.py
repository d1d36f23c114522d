"""Networks for one part: a PSF pair checked against the network's design and fitted to its window, told to the
network, and the network alone fine-tuned on captures through the pair (tiny HDR network, seconds)."""

import hashlib

import numpy as np
import pytest
import torch

from doefab.errors import DoefabError
from doefab.optics.psf import PSFPair
from doefab.reconstruction.partfinetune import check_capture, finetune_on_pair, fit_to_network

TINY = {"features": 1, "width": 4, "highlight_iters": 5, "bound_iters": 4, "bound_rounds": 2}
SMALL = dict(minutes=10, crop=64, val_images=1, batch=1, val_every=1, progress=False)


def _pair(k: int, wavelengths=(550e-9, 650e-9), depths=(2.0, 5.0), pitch=5.4e-6, fill=None) -> PSFPair:
    shape = (len(depths), len(wavelengths), k, k)
    coded = torch.zeros(shape) if fill is None else fill(shape)
    return PSFPair(coded, coded.clone(), tuple(wavelengths), tuple(depths), pitch)


@pytest.fixture(scope="module")
def start(tmp_path_factory):
    """A tiny HDR network trained one step for the committed streak design, and that design's pair."""
    from doefab.reconstruction.specs import psf_pair
    from doefab.reconstruction.train import train

    root = tmp_path_factory.mktemp("pft")
    train("hdr", "proposed", minutes=1, out_dir=root / "t", weights_dir=root / "w", crop=64, val_images=1,
          val_every=100, arch=TINY, progress=False, max_steps=1)
    return root / "w", psf_pair("hdr")[0]


def test_a_pair_is_fitted_to_the_networks_window_about_the_chief_ray():
    net = _pair(9)
    small = _pair(5)
    small.coded[..., 2, 2] = 0.3  # the chief ray
    small.coded[..., 0, 4] = 0.1  # two rows up, two columns right of it
    got = fit_to_network(small, net, "hdr")
    want = np.zeros((2, 2, 9, 9), np.float32)
    want[..., 4, 4], want[..., 2, 6] = 0.3, 0.1
    assert got.coded.shape == net.coded.shape and np.array_equal(got.coded.numpy(), want)
    big = _pair(13)
    big.coded[..., 6, 6], big.coded[..., 0, 0] = 0.3, 0.2  # the corner lies outside the network's window
    cropped = fit_to_network(big, net, "hdr").coded
    assert float(cropped[0, 0, 4, 4]) == pytest.approx(0.3) and float(cropped.sum()) == pytest.approx(4 * 0.3)


@pytest.mark.parametrize("change, needle", [
    ({"wavelengths": (550e-9,)}, "1 band 550 nm (the network: 2 bands 550, 650 nm)"),
    ({"depths": (2.0, 4.0)}, "depth planes 2, 4 m (the network: 2, 5 m)"),
    ({"pitch": 3.76e-6}, "sensor pitch 3.76 µm (the network: 5.4 µm)")])
def test_a_pair_of_other_bands_planes_or_pitch_is_refused_with_the_fix(change, needle):
    with pytest.raises(DoefabError) as exc:
        fit_to_network(_pair(9, **change), _pair(9), "depth")
    msg = str(exc.value)
    assert msg.startswith("--psf:") and needle in msg and "psf_pair_fitted.npz" in msg


def test_captures_may_come_through_finer_planes_but_not_another_camera():
    check_capture(_pair(15, depths=(2.0, 3.0, 4.0, 5.0)), _pair(9), "--capture-psf")  # a model at finer planes
    with pytest.raises(DoefabError, match="--capture-psf: the PSF pair is for sensor pitch 3.76 µm"):
        check_capture(_pair(9, pitch=3.76e-6), _pair(9), "--capture-psf")


def test_the_network_is_told_the_pair(start, tmp_path):
    """The same captures (through the nominal pair); the network told the nominal pair starts at exactly the metric
    the starting network scores with its own pair, and told a pair without coded light, at another one."""
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.specs import make_batch
    from doefab.reconstruction.train import evaluate_batch, model_inputs

    weights, nominal = start
    dark = PSFPair(torch.zeros_like(nominal.coded), nominal.uncoded, nominal.wavelengths, nominal.depths,
                   nominal.sensor_pitch)
    told_nominal = finetune_on_pair("hdr", nominal, tmp_path / "a", weights_dir=weights, max_steps=1, **SMALL)
    told_dark = finetune_on_pair("hdr", dark, tmp_path / "b", capture_pair=nominal, weights_dir=weights,
                                 max_steps=1, **SMALL)
    rec = load_reconstructor("hdr", weights_dir=weights)
    val = make_batch("hdr", "val", range(1), 64, nominal, None, Sensor().noise())
    own = evaluate_batch("hdr", rec.model, *val, model_inputs("hdr", nominal))["psnr"]
    assert told_nominal["val_start"] == pytest.approx(own, abs=1e-6)
    assert abs(told_dark["val_start"] - own) > 1.0


def test_the_network_alone_trains_on_captures_through_the_pair_and_resumes(start, tmp_path, monkeypatch):
    import doefab.reconstruction.train as training
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.specs import design_dir

    weights, nominal = start
    part = PSFPair(torch.roll(nominal.coded, 2, dims=-1), nominal.uncoded, nominal.wavelengths, nominal.depths,
                   nominal.sensor_pitch, provenance={"source": "calibrate"})
    seen, make_batch = [], training.make_batch

    def spy(task, split, indices, size, pair, *a, **kw):
        seen.append((split, pair))
        return make_batch(task, split, indices, size, pair, *a, **kw)

    monkeypatch.setattr(training, "make_batch", spy)
    committed = {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in design_dir("hdr").iterdir()}
    out = tmp_path / "run"
    res = finetune_on_pair("hdr", part, out, weights_dir=weights, max_steps=1, **SMALL)
    assert res["steps"] == 1 and {s for s, _ in seen} == {"train", "val"} and all(p is part for _, p in seen)
    rec = load_reconstructor("hdr", weights_dir=out / "weights")  # torch.load(weights_only=True) inside
    before = load_reconstructor("hdr", weights_dir=weights)
    assert any(not torch.equal(a, b) for a, b in zip(rec.model.state_dict().values(),
                                                     before.model.state_dict().values()))
    ft = rec.meta["training"]["fine_tune"]
    assert ft["told"]["provenance"] == {"source": "calibrate"} and ft["start_weights_sha256"] == \
        before.meta["weights_sha256"]
    assert rec.design_sha256 == before.design_sha256  # the same design: the DOE was not touched
    assert not (out / "design").exists()
    assert {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in design_dir("hdr").iterdir()} == committed
    more = finetune_on_pair("hdr", part, out, weights_dir=weights, max_steps=2, resume=True, **SMALL)
    assert more["steps"] == 2
    rows = (out / "history.csv").read_text().splitlines()
    assert rows[0] == "step,wall_time_s,loss,val_psnr" and [r.split(",")[0] for r in rows[1:]] == ["0", "1", "1",
                                                                                                    "2", "2"]
    with pytest.raises(DoefabError, match="other settings"):  # another pair is another run
        finetune_on_pair("hdr", nominal, out, weights_dir=weights, max_steps=3, resume=True, **SMALL)
