import json
import math

import numpy as np
import pytest

from doefab.reconstruction.metrics import depth_metrics, hdr_metrics, spectral_metrics


def test_hdr_metrics_use_peak_256_and_highlights():
    t = np.ones((3, 8, 8))
    t[:, 0, 0] = 100.0  # one highlight pixel
    p = t.copy()
    p[:, 0, 0] = 90.0
    m = hdr_metrics(p, t)
    mse = 100 * 3 / (3 * 64)
    assert m["rmse"] == pytest.approx(math.sqrt(mse)) and m["psnr"] == pytest.approx(10 * math.log10(256**2 / mse))
    assert m["rmse_highlight"] == pytest.approx(10.0)


def test_spectral_and_depth_metrics():
    rng = np.random.default_rng(0)
    t = rng.random((31, 16, 16))
    m = spectral_metrics(t, t)
    assert m["sam"] == pytest.approx(0, abs=1e-6) and m["ssim"] == pytest.approx(1)
    assert spectral_metrics(2 * t, t)["sam"] == pytest.approx(0, abs=1e-6)  # SAM ignores scale
    d = np.full((4, 4), 2.0)
    m = depth_metrics(d * 1.3, d)
    assert m["mae"] == pytest.approx(0.6) and m["delta125"] == 0.0 and m["log10"] == pytest.approx(math.log10(1.3))


def test_evaluate_writes_the_three_rows(tmp_path):
    from doefab.reconstruction.evaluate import evaluate
    from doefab.reconstruction.train import train

    for v in ("proposed", "coded_only", "uncoded_only"):
        train("hdr", v, minutes=1, out_dir=tmp_path / v, weights_dir=tmp_path / "w", crop=64, val_images=1,
              val_every=100, arch={"features": 1, "width": 4}, progress=False,
              max_steps=1)
    res = evaluate("hdr", tmp_path / "eval", images=2, size=64, weights_dir=tmp_path / "w", progress=False)
    saved = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert saved["task"] == "hdr" and saved["images"] == 2 and saved["split"] == "test" and set(saved["rows"]) == {
        "proposed", "coded_only", "uncoded_only"}
    assert set(saved["rows"]["proposed"]) == {"rmse", "psnr", "rmse_highlight", "psnr_highlight"}
    assert (tmp_path / "eval" / "examples.png").stat().st_size > 10_000
    # each variant's row is its own reconstruction's PSNR (peak 2^8), scene by scene: recomputed here from the test
    # scenes' captures (scene i of 2 at its place, the default sensor's noise) and the saved weights
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.loader import load_reconstructor
    from doefab.reconstruction.specs import make_batch, psf_pair

    pair, _ = psf_pair("hdr")
    scenes = [make_batch("hdr", "test", [i], 64, pair, None, Sensor().noise(), images=2) for i in range(2)]
    psnr = {}
    for v in saved["rows"]:
        rec = load_reconstructor("hdr", v, tmp_path / "w")
        psnr[v] = [10 * math.log10(256.0**2 / float(np.mean((np.asarray(rec(c[0], u[0])) - t[0].numpy()) ** 2)))
                   for c, u, t in scenes]
        assert [r["psnr"] for r in saved["per_image"]["rows"][v]] == pytest.approx(psnr[v], abs=1e-3), v
        assert saved["rows"][v]["psnr"] == pytest.approx(np.mean(psnr[v]), abs=1e-3) == res["rows"][v]["psnr"]
    assert len({round(p[0], 3) for p in psnr.values()}) == 3  # three networks, three reconstructions
    # the weights name the splits they were trained on, and the evaluation says whether its scenes come from them
    states = {v: w["splits"] for v, w in saved["weights"].items()}
    assert set(states.values()) == {"the same splits"}, states
    import doefab.reconstruction.evaluate as ev

    rec = json.loads((tmp_path / "w" / "hdr_proposed.json").read_text())
    assert len(rec["splits_sha256"]) == 64
    other = {**rec["splits_components"], "splits": "0" * 64}
    assert ev._splits_state(rec, "hdr", other).startswith("ANOTHER split definition (splits)")


def test_the_evaluation_records_the_cameras_sensor_and_its_noise_reaches_the_captures(tmp_path):
    """The shipped HDR network on one validation scene: the default sensor's captures, then a sensor with 200 e⁻
    full well and 20 e⁻ read noise (refused unless asked for: the network was trained for 25 000 e⁻ / 3 e⁻);
    its noise costs image PSNR."""
    from doefab.errors import DoefabError
    from doefab.imaging.sensor import Sensor
    from doefab.reconstruction.evaluate import evaluate

    kw = dict(images=1, size=64, progress=False, variants=("uncoded_only",), split="val")
    quiet = evaluate("hdr", tmp_path / "a", **kw)
    noisy_sensor = Sensor(full_well_e=200.0, read_noise_e=20.0)
    with pytest.raises(DoefabError, match="another sensor"):
        evaluate("hdr", tmp_path / "b", sensor=noisy_sensor, **kw)
    noisy = evaluate("hdr", tmp_path / "b", sensor=noisy_sensor, other_design=True, **kw)
    # the default sensor's evaluation records what it did before sensors could be named (the committed tables)
    assert "sensor" not in quiet and quiet["noise"] == "default (Poisson–Gaussian)"
    assert noisy["sensor"] == {"full_well_e": 200.0, "read_noise_e": 20.0}
    assert noisy["noise"] == "Poisson–Gaussian, 200 e⁻ full well, 20 e⁻ read noise"
    assert "for_this_sensor" not in quiet["weights"]["uncoded_only"]
    assert noisy["weights"]["uncoded_only"]["for_this_sensor"] is False
    assert noisy["rows"]["uncoded_only"]["psnr"] < quiet["rows"]["uncoded_only"]["psnr"] - 3


def test_the_split_digest_follows_the_content_of_the_splits(monkeypatch):
    """A network trained on other splits is noticed: moving one photograph between splits, or one reflectance
    family, changes the digest; the tasks that use no spectra do not depend on the spectra."""
    from doefab.reconstruction import data, spectra

    hdr, hs = data.split_digest("hdr"), data.split_digest("hyperspectral")
    assert hdr != hs
    moved = {**data.IMAGES, "train": data.IMAGES["train"][1:], "test": data.IMAGES["test"] + data.IMAGES["train"][:1]}
    monkeypatch.setattr(data, "IMAGES", moved)
    assert data.split_digest("hdr") != hdr
    monkeypatch.undo()
    real = spectra.reflectances
    monkeypatch.setattr(spectra, "reflectances", lambda s: real(s)[1:] if s == "train" else real(s))
    assert data.split_digest("hyperspectral") != hs and data.split_digest("hdr") == hdr


def test_mean_metrics_skips_images_without_the_metric_quietly():
    import warnings

    from doefab.reconstruction.metrics import mean_metrics

    rows = [{"psnr": 30.0, "psnr_highlight": float("nan")}, {"psnr": 40.0, "psnr_highlight": 20.0}]
    assert mean_metrics(rows) == {"psnr": 35.0, "psnr_highlight": 20.0}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "Mean of empty slice" when no image has highlights
        out = mean_metrics([{"psnr": 30.0, "psnr_highlight": float("nan")}])
    assert out["psnr"] == 30.0 and np.isnan(out["psnr_highlight"])
