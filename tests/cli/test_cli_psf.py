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
    """--design: the PSFs of the design's L-level map (level · level_step_m, read here from design.json) on its own
    camera — the same as that map given with --height on the camera's preset — and its bands and depths."""
    import json

    import numpy as np

    from doefab.cli.psf import _source

    design = REPO / "masks" / "streak" / "design"
    record = json.loads((design / "design.json").read_text())
    height = np.load(design / "levels.npy").astype(np.float64) * record["level_step_m"]
    np.save(tmp_path / "h.npy", height)
    _, _, lams, depths, kernel, _ = _source(_args(["--design", str(design.parent)]))
    assert lams == record["wavelengths_m"] and depths == record["depths_m"]
    assert kernel == record["task_params"]["kernel_size"]
    flags = ["--wavelengths-nm", "589", "--kernel", "31"]
    assert main(["psf", "--design", str(design.parent), *flags, "--out", str(tmp_path / "d")]) == 0
    assert main(["psf", "--preset", "hdr", "--height", str(tmp_path / "h.npy"), "--depths-m", str(depths[0]),
                 *flags, "--out", str(tmp_path / "h")]) == 0
    assert main(["psf", "--preset", "hdr", "--depths-m", str(depths[0]), *flags, "--out", str(tmp_path / "b")]) == 0
    d, h, b = (np.load(tmp_path / k / "psf.npz") for k in "dhb")
    assert np.allclose(d["coded"], h["coded"], atol=1e-7) and np.allclose(d["uncoded"], b["uncoded"], atol=1e-7)
    assert np.abs(d["coded"] - b["coded"]).max() > 1e-3  # the DOE is there: not the blank part's PSF
    assert float(d["depths_m"][0]) == depths[0]


def test_scene_gives_its_camera_bands_depths_and_window(tmp_path, capsys):
    """--scene: the scene's camera (its 3.76 µm sensor pixels, 8.75 mm DOE aperture at 4 µm: 2188² pixels), its
    21 bands and its window, as the scene file states them; a height map of another grid names the scene."""
    import numpy as np

    from doefab.cli.psf import _source

    scene = REPO / "scenes" / "my_camera.toml"
    cam, height, lams, depths, kernel, _ = _source(_args(["--scene", str(scene)]))
    assert height is None and kernel == 191 and cam.doe_pixels == 2188
    assert np.allclose(lams, np.arange(450, 651, 10) * 1e-9)
    assert main(["psf", "--scene", str(scene), "--wavelengths-nm", "550", "--kernel", "31", "--out",
                 str(tmp_path / "s")]) == 0
    s = np.load(tmp_path / "s" / "psf.npz")
    assert abs(float(s["sensor_pitch_m"]) - 3.76e-6) < 1e-15 and s["coded"].shape == (len(depths), 1, 31, 31)
    np.save(tmp_path / "h.npy", np.zeros((3200, 3200)))
    assert main(["psf", "--scene", str(scene), "--height", str(tmp_path / "h.npy"), "--out", str(tmp_path / "x")]) == 2
    assert "my_camera.toml's DOE grid is (2188, 2188)" in capsys.readouterr().err
