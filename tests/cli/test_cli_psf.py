"""``doefab psf``: --force replaces only doefab's own output, which carries its marker; --design and --scene give
their camera, bands, depths and window (and --design its L-level DOE)."""

from pathlib import Path

from doefab.cli import main
from doefab.io import MARKER

REPO = Path(__file__).resolve().parents[2]


def test_force_replaces_only_own_output_and_marker_is_written(tmp_path, capsys):
    out = tmp_path / "p"
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)]) == 0
    assert (out / MARKER).is_file()
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out), "--force"]) == 0


def _args(argv):
    import argparse

    from doefab.cli import psf

    parser = argparse.ArgumentParser()
    psf.register(parser.add_subparsers())
    return parser.parse_args(["psf", *argv, "--out", "unused"])


def test_design_gives_its_quantized_doe_camera_bands_and_depths(tmp_path):
    """--design: the PSFs of the design's L-level map (level · level_step_m, read here from design.json), not its
    continuous one, on its own camera — the same as that map given with --height on the camera's preset — and its
    own bands, depths and window (a copy of the streak design with bands, planes, a window and a continuous
    height.npy of its own)."""
    import json
    import shutil

    import numpy as np

    from doefab.cli.psf import _source

    design = tmp_path / "set" / "design"  # a mask set's design, given as the set
    shutil.copytree(REPO / "masks" / "streak" / "design", design)
    record = json.loads((design / "design.json").read_text())
    record["wavelengths_m"], record["depths_m"] = [6.3e-7, 5.3e-7, 4.6e-7], [4.0, "inf"]
    record["task_params"]["kernel_size"] = 101
    (design / "design.json").write_text(json.dumps(record))
    height = np.load(design / "levels.npy").astype(np.float64) * record["level_step_m"]
    np.save(tmp_path / "h.npy", height)
    np.save(design / "height.npy", height + 0.3 * record["level_step_m"])  # the continuous design: not made
    _, h, lams, depths, kernel, _ = _source(_args(["--design", str(design.parent)]))
    assert lams == [6.3e-7, 5.3e-7, 4.6e-7] and depths == [4.0, float("inf")] and kernel == 101
    assert np.allclose(h, height, rtol=1e-12, atol=0)
    flags = ["--wavelengths-nm", "589", "--kernel", "31", "--depths-m", "4"]
    assert main(["psf", "--design", str(design.parent), *flags, "--out", str(tmp_path / "d")]) == 0
    assert main(["psf", "--preset", "hdr", "--height", str(tmp_path / "h.npy"), *flags,
                 "--out", str(tmp_path / "h")]) == 0
    assert main(["psf", "--preset", "hdr", *flags, "--out", str(tmp_path / "b")]) == 0
    d, h, b = (np.load(tmp_path / k / "psf.npz") for k in "dhb")
    assert np.allclose(d["coded"], h["coded"], atol=1e-7) and np.allclose(d["uncoded"], b["uncoded"], atol=1e-7)
    assert np.abs(d["coded"] - b["coded"]).max() > 1e-3  # the DOE is there: not the blank part's PSF


def test_scene_gives_its_camera_bands_depths_and_window(tmp_path, capsys):
    """--scene: the scene's camera (my_camera.toml's 3.76 µm sensor pixels, 8.75 mm DOE aperture at 4 µm: 2188²
    pixels), and a depth scene's own bands, depth planes and window, as the scene files state them; a height map of
    another grid names the scene."""
    import numpy as np

    from doefab.cli.psf import _source

    text = (REPO / "scenes" / "depth.toml").read_text()
    optics = text[text.index("[optics]"):text.index("[design]")]
    depth = tmp_path / "depth.toml"
    text = text.replace('material = "fused silica"', 'material = "PMMA"')  # fitted on 436.8–1052 nm
    depth.write_text(text.replace(optics, "[optics]\nwavelengths_nm = [640, 550, 430]\ndepths_m = [1.5, 2.5, 4.0]\n"
                                          "kernel_px = 71\n\n"))
    capsys.readouterr()
    _, height, lams, depths, kernel, _ = _source(_args(["--scene", str(depth)]))
    assert height is None and kernel == 71 and depths == [1.5, 2.5, 4.0]
    assert np.allclose(lams, [640e-9, 550e-9, 430e-9], rtol=0, atol=1e-15)
    assert "warning: PMMA: 430 nm outside" in capsys.readouterr().out  # the scene's own warnings
    _source(_args(["--scene", str(depth), "--wavelengths-nm", "550"]))
    assert "warning" not in capsys.readouterr().out  # about bands not used: dropped
    _source(_args(["--scene", str(depth), "--wavelengths-nm", "420", "550"]))
    assert "warning: PMMA: 420 nm outside" in capsys.readouterr().out  # the bands used
    mine = REPO / "scenes" / "my_camera.toml"
    cam, _, lams, _, _, _ = _source(_args(["--scene", str(mine)]))
    assert cam.doe_pixels == 2188 and np.allclose(lams, np.arange(450, 651, 10) * 1e-9)
    assert main(["psf", "--scene", str(mine), "--wavelengths-nm", "550", "--kernel", "31", "--out",
                 str(tmp_path / "s")]) == 0
    s = np.load(tmp_path / "s" / "psf.npz")
    assert abs(float(s["sensor_pitch_m"]) - 3.76e-6) < 1e-15 and s["coded"].shape == (1, 1, 31, 31)
    np.save(tmp_path / "h.npy", np.zeros((3200, 3200)))
    assert main(["psf", "--scene", str(mine), "--height", str(tmp_path / "h.npy"), "--out", str(tmp_path / "x")]) == 2
    assert "my_camera.toml's DOE grid is (2188, 2188)" in capsys.readouterr().err


def test_help_shows_the_examples_on_their_own_lines_and_no_none_default(capsys):
    import pytest

    with pytest.raises(SystemExit):
        main(["psf", "--help"])
    text = capsys.readouterr().out
    assert "\n  doefab psf --design masks/streak --out out/psf_streak\n" in text
    assert "default: None" not in text and "(default: spectral)" in text


def test_many_bands_are_labelled_by_their_span():
    from doefab.cli.psf import _bands

    assert _bands([w * 1e-9 for w in range(700, 390, -10)]) == "31 bands 400–700"
    assert _bands([656e-9, 589e-9]) == "656, 589"
