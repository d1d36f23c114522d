"""The measured depth scenes of the measured-data validation set beyond the Motorcycle: the Middlebury 2014 scenes
``doefab/measured/middlebury_depth.npz`` holds (``scripts/measured_depth.py`` wrote it)."""

import hashlib
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from doefab.reconstruction import realdata

ROOT = Path(__file__).resolve().parents[2]
PIANO_CALIB = ("cam0=[ 713.189 0 356.021 ; 0 713.189 238.263 ; 0 0 1 ]\ncam1=[ 713.189 0 387.361 ; 0 713.189 238.263 ; "
               "0 0 1 ]\ndoffs= 31.34\nbaseline= 178.089\nwidth= 707\nheight= 481\nndisp= 65\n")


def _script():
    spec = importlib.util.spec_from_file_location("measured_depth", ROOT / "scripts" / "measured_depth.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_calibration_is_read_from_middlebury_calib_text_in_si_units():
    """Piano's calib.txt as MiddEval3 publishes it: focal length and doffs in pixels, the baseline given in mm."""
    c = _script().calibration(PIANO_CALIB)
    assert c == {"focal_px": 713.189, "baseline_m": pytest.approx(0.178089, rel=1e-12), "doffs_px": 31.34}


def test_the_depth_file_is_what_its_script_wrote():
    """The script's scenes, each image the source PNG byte for byte (its recorded SHA-256), each disparity a 16-bit
    PNG of the recorded scale, each calibration inside the range of focal lengths and baselines of the 2014 rig."""
    import imageio.v3 as iio

    with np.load(realdata.DEPTH_FILE) as z:
        sources = json.loads(str(z["sources"]))
        assert tuple(sources) == _script().SCENES
        for name, src in sources.items():
            png = z[f"{name}_image_png"].tobytes()
            assert hashlib.sha256(png).hexdigest() == src["files"]["im0.png"]["sha256"]
            disp = iio.imread(z[f"{name}_disparity_png"].tobytes())
            assert disp.dtype == np.uint16 and disp.shape == iio.imread(png).shape[:2]
            c = src["calibration"]
            assert 500 < c["focal_px"] < 2000 and 0.15 < c["baseline_m"] < 0.4 and 0 < c["doffs_px"] < 250


def test_each_scene_is_its_calibration_of_the_measured_disparity():
    """Z = f·B / (d + doffs) at each measured pixel, from the file's PNG and calibration read here; inside the shipped
    design's 1–5 m (to 2 cm at the near end: Vintage's nearest 0.98 m is clipped to the design's near plane); each
    unmeasured pixel the depth of a measured pixel at the nearest distance (brute force on a sample)."""
    import imageio.v3 as iio

    rng = np.random.default_rng(0)
    got = {name: rest for name, *rest in realdata.depth_scenes()}
    with np.load(realdata.DEPTH_FILE) as z:
        for name, src in json.loads(str(z["sources"])).items():
            img, depth, known = got[name]
            steps = iio.imread(z[f"{name}_disparity_png"].tobytes()).astype(np.float64)
            c = src["calibration"]
            assert np.array_equal(known, steps > 0) and known.mean() > 0.85
            zz = c["focal_px"] * c["baseline_m"] / (steps[known] / 256.0 + c["doffs_px"])
            assert np.allclose(depth[known], zz, rtol=1e-6) and 0.97 < zz.min() and zz.max() < 5.0
            lin = (iio.imread(z[f"{name}_image_png"].tobytes()) / 255.0) ** 2.2
            assert np.allclose(img, lin, rtol=1e-5, atol=1e-7)
            ky, kx = np.nonzero(known)
            uy, ux = np.nonzero(~known)
            for i in rng.choice(len(uy), 5, replace=False):
                d2 = (ky - uy[i]) ** 2 + (kx - ux[i]) ** 2
                assert np.isclose(depth[uy[i], ux[i]], depth[ky[d2 == d2.min()], kx[d2 == d2.min()]], rtol=1e-6).any()



def test_the_script_stores_the_disparity_top_row_first_in_steps_of_a_256th_and_none_as_zero(tmp_path, monkeypatch):
    """A made-up scene in MiddEval3's layout: a PFM written here (rows bottom to top, as the format stores them) with
    one pixel without ground truth; the stored 16-bit PNG is round(256·d) top row first, 0 there; the image PNG is
    the file byte for byte; the calibration is Piano's text read in SI units."""
    import imageio.v3 as iio

    rng = np.random.default_rng(1)
    disp = rng.uniform(5.0, 150.0, (6, 9)).astype(np.float32)
    disp[1, 2] = np.inf
    data = tmp_path / "MiddEval3" / "trainingQ" / "Made"
    gt = tmp_path / "MiddEval3GT" / "trainingQ" / "Made"
    data.mkdir(parents=True)
    gt.mkdir(parents=True)
    iio.imwrite(data / "im0.png", rng.integers(0, 256, (6, 9, 3), dtype=np.uint8))
    (data / "calib.txt").write_text(PIANO_CALIB)
    (gt / "disp0GT.pfm").write_bytes(b"Pf\n9 6\n-1.0\n" + np.ascontiguousarray(disp[::-1]).astype("<f4").tobytes())
    mod = _script()
    monkeypatch.setattr(mod, "SCENES", ("Made",))
    monkeypatch.setattr(mod, "OUT", tmp_path / "out.npz")
    mod.main(str(tmp_path))
    with np.load(tmp_path / "out.npz") as z:
        src = json.loads(str(z["sources"]))["Made"]
        assert z["Made_image_png"].tobytes() == (data / "im0.png").read_bytes()
        steps = iio.imread(z["Made_disparity_png"].tobytes())
    want = np.where(np.isfinite(disp), np.round(disp.astype(np.float64) * 256), 0)
    assert steps.dtype == np.uint16 and np.array_equal(steps, want) and steps[1, 2] == 0
    assert src["calibration"]["baseline_m"] == pytest.approx(0.178089)
