"""``doefab calibrate`` end to end on recordings a simulated lab wrote: the three files, and a bad recording refused
with one line (exit 2) and nothing written."""

import json

import numpy as np
import pytest

import doefab


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory):
    """A one-band streak design on a 100-pixel DOE (kernel 31 px)."""
    from doefab.design.design import Design
    from doefab.tasks import get_task

    cam = doefab.Camera(aperture_diameter=1.08e-3, doe_pitch=10.8e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=40e-3, focus_distance=5.0)
    task = get_task("streak", kernel_size=31, arm_px=6)
    task.bind(cam)
    lv = doefab.quantize_levels(task.init_height(cam, np.random.default_rng(0)), cam)
    lv[:, 50:] = 15
    d = Design(task="streak", task_params=task.params(), camera=cam, wavelengths=(589e-9,), depths=(5.0,),
               height=doefab.levels_to_height(lv, cam), levels=lv, metrics={"name": "m", "continuous": 0.5,
                                                                            "quantized": 0.5})
    root = tmp_path_factory.mktemp("design")
    d.save(root / "design")
    return root / "design"


@pytest.fixture(scope="module")
def lab(design_dir, tmp_path_factory):
    """Recordings (16-bit TIFFs, darks, both white-wall pairs) of the design's nominal part."""
    from doefab.lab.simulate import write_lab_recordings

    folder = tmp_path_factory.mktemp("lab") / "rec"
    return write_lab_recordings(folder, design_dir, supersample=1, frames=3, dark_frames=2, shift_px=(0.4, -0.3),
                                crosstalk=(0.05, 0.04), seed=1)


def test_calibrate_writes_the_three_files(lab, tmp_path, capsys):
    from doefab.cli import main

    out = tmp_path / "cal"
    assert main(["calibrate", str(lab), "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} >= {"psf_pair.npz", "crosstalk.json", "calibration.html"}
    assert "crosstalk (column means)" in capsys.readouterr().out
    pair = doefab.PSFPair.load(out / "psf_pair.npz")
    assert pair.coded.shape == (1, 1, 31, 31) and pair.provenance["source"] == "calibrate"
    cam = doefab.DualPixelCrosstalk.load(out / "crosstalk.json")
    for est, se, true in ((cam.alpha_lr, cam.standard_error[0], 0.05), (cam.alpha_rl, cam.standard_error[1], 0.04)):
        assert abs(np.mean(est) - true) < 3 * np.sqrt(np.mean(se ** 2) / se.size)  # the mean over columns
    assert json.loads((out / "crosstalk.json").read_text())["columns"] == 62
    # a second run into the same folder needs --force
    assert main(["calibrate", str(lab), "--out", str(out)]) == 2
    assert main(["calibrate", str(lab), "--out", str(out), "--force"]) == 0
    # replaced by a calibration without [[wall]] pairs: the earlier crosstalk.json goes with it (left beside the
    # new PSF pair it would read as this calibration's)
    no_walls = lab.parent / "no_walls.toml"
    no_walls.write_text(lab.read_text().split("[[wall]]")[0])
    assert main(["calibrate", str(no_walls), "--out", str(out), "--force"]) == 0
    assert {p.name for p in out.iterdir()} == {"psf_pair.npz", "calibration.html", ".doefab-output.json"}


def test_a_bad_recording_exits_2_and_writes_nothing(lab, design_dir, one_clear_error, tmp_path_factory):
    import shutil

    bad = tmp_path_factory.mktemp("bad") / "rec"
    shutil.copytree(lab.parent, bad)
    frame = sorted((bad / "psf").glob("coded_*_1.tiff"))[0]
    frame.write_bytes(frame.read_bytes()[:200])  # a truncated TIFF
    one_clear_error(lambda fx, work: ["calibrate", bad / "recordings.toml", "--design", design_dir, "--out", "cal"],
                    2, frame.name)
