"""Simulated lab recordings of a part: they pass the recordings checks, each frame holds the photo-electrons asked
(within the shot and read noise), the PSF sits at the asked sub-pixel offset of the part's own PSF (computed here
independently), and the white-wall views carry the crosstalk asked (Eq. 29)."""

import json
import math

import numpy as np
import pytest

import doefab
from doefab.design.design import Design
from doefab.errors import DoefabError
from doefab.lab.frames import mean_frames, read_frame
from doefab.lab.recordings import check_recordings, load_recordings
from doefab.lab.simulate import write_lab_recordings
from doefab.tasks.grating import GratingTask
from doefab.tolerance.errors import PartErrors
from doefab.tolerance.judge import PSFJudge

K = 31
SHIFT = (0.3, -0.45)
PART = PartErrors(depth_scale=(1.04, 1.0, 0.97, 1.0), overlay=((1e-6, 0.0),) + ((0.0, 0.0),) * 3)
CROSSTALK = (0.06, 0.03)
BANDS = (400e-9, 550e-9, 700e-9)  # GratingTask(n_bands=3)


@pytest.fixture(scope="module")
def design_dir(tmp_path_factory):
    """A 64-px blazed grating (period 16 px) over the coded half at f/14: compact PSFs within a 2K frame."""
    n, pitch = 64, 5.4e-6
    cam = doefab.Camera(aperture_diameter=n * pitch, doe_pitch=pitch, doe_pixels=n, sensor_pitch=pitch,
                        sensor_distance=5e-3, focus_distance=2.0)
    task = GratingTask(kernel_size=K, n_bands=3)
    task.bind(cam)
    lv = doefab.quantize_levels(doefab.blazed_grating_height(cam, period_pixels=16), cam)
    lv[:, n // 2:] = 15
    d = Design(task="grating", task_params=task.params(), camera=cam, wavelengths=task.wavelengths(cam),
               depths=(2.0, math.inf), height=doefab.levels_to_height(lv, cam), levels=lv,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    return d.save(tmp_path_factory.mktemp("lab") / "design")


@pytest.fixture(scope="module")
def recorded(design_dir, tmp_path_factory):
    folder = tmp_path_factory.mktemp("rec") / "recordings"
    toml = write_lab_recordings(folder, design_dir, PART, wavelengths_m=[550e-9], depths_m=[math.inf],
                                photons=2e6, shift_px=SHIFT, frames=4, dark_frames=2, crosstalk=CROSSTALK)
    return toml, json.loads((folder / "truth.json").read_text())


def test_recordings_pass_the_checks_and_hold_the_photons_asked(recorded, design_dir):
    toml, truth = recorded
    rec = load_recordings(toml)
    assert rec.design == design_dir.resolve()
    assert [(r.half, r.view, r.depth_m) for r in rec.psf] == [("coded", "coded", math.inf),
                                                              ("plain", "plain", math.inf)]
    assert [r.wavelength_m for r in rec.psf] == pytest.approx([550e-9] * 2)
    check_recordings(rec, BANDS, (2.0, math.inf), K)  # raises on any problem
    g, read, npx = truth["gain_e_per_dn"], truth["read_noise_e"], truth["size_px"] ** 2
    for r in rec.psf:
        dark, nd = mean_frames(r.dark)
        sums = [float((read_frame(p) - dark).sum()) * g for p in r.frames]
        # shot noise of the photons and read (+ rounding) noise of every pixel, per frame; the darks' mean is shared
        var = (2e6 + npx * (read**2 + g**2 / 12)) / len(sums) + npx * (read**2 + g**2 / 12) / nd
        assert abs(np.mean(sums) - 2e6) < 4 * math.sqrt(var), (r.half, np.mean(sums))


def _centroid(img):
    y, x = np.mgrid[:img.shape[0], :img.shape[1]]
    return np.array([(img * y).sum(), (img * x).sum()]) / img.sum()


def test_psf_sits_at_the_asked_subpixel_offset(recorded, design_dir):
    toml, truth = recorded
    size = truth["size_px"]
    judge = PSFJudge(design_dir, 2)  # the part's PSFs, independently: all bands and planes, no offset
    psfs = judge.psfs(PART, halves=("coded", "uncoded"), kernel=size)
    rec = load_recordings(toml)
    for r, half in zip(rec.psf, ("coded", "uncoded")):
        frame = mean_frames(r.frames)[0] - mean_frames(r.dark)[0]
        moved = _centroid(frame) - _centroid(psfs[half][1, 1].double().numpy())
        np.testing.assert_allclose(moved, SHIFT, atol=0.05, err_msg=half)


def test_wall_views_carry_the_crosstalk(recorded):
    toml, truth = recorded
    a, b = CROSSTALK  # α_l→r: plain (left) view's light reaching the coded (right) view; α_r→l the reverse
    rec = load_recordings(toml)
    level = truth["wall_level_e"] / truth["gain_e_per_dn"]
    for w in rec.wall:
        dark = mean_frames(w.dark)[0]
        coded = mean_frames(w.coded_view)[0].mean() - dark.mean()
        plain = mean_frames(w.plain_view)[0].mean() - dark.mean()
        if w.half == "coded":  # R* = (1 − b) R, L* = b R
            assert coded == pytest.approx((1 - b) * level, rel=2e-3) and plain == pytest.approx(b * level, rel=2e-3)
        else:  # L* = (1 − a) L, R* = a L
            assert plain == pytest.approx((1 - a) * level, rel=2e-3) and coded == pytest.approx(a * level, rel=2e-3)
    assert sorted(w.half for w in rec.wall) == ["coded", "plain"]


def test_bad_arguments_are_refused_before_anything_is_written(design_dir, tmp_path):
    out = tmp_path / "rec"
    with pytest.raises(DoefabError, match=r"wavelengths_m = 6e-07 m is not one of the design's: use some of "
                                          r"400, 550, 700 nm"):
        write_lab_recordings(out, design_dir, wavelengths_m=[600e-9])
    with pytest.raises(DoefabError, match=r"depths_m = 3 m is not one of the design's: use some of 2, inf m"):
        write_lab_recordings(out, design_dir, depths_m=[3.0])
    with pytest.raises(DoefabError, match="photons must be > 0"):
        write_lab_recordings(out, design_dir, photons=0)
    with pytest.raises(DoefabError, match="crosstalk"):
        write_lab_recordings(out, design_dir, crosstalk=(0.6, 0.5))
    assert not out.exists()
    out.mkdir()
    (out / "mine.txt").write_text("x")
    with pytest.raises(DoefabError, match="not empty: give a new or empty folder"):
        write_lab_recordings(out, design_dir)
    assert [p.name for p in out.iterdir()] == ["mine.txt"]


def test_too_few_photons_are_caught_by_the_checks(design_dir, tmp_path):
    toml = write_lab_recordings(tmp_path / "dim", design_dir, wavelengths_m=[550e-9], depths_m=[2.0], photons=2e3,
                                frames=2, dark_frames=0, wall=False)
    assert not (tmp_path / "dim" / "wall").exists() and "dark" not in toml.read_text()  # the black level instead
    with pytest.raises(DoefabError, match=r"coded_b1_d0_0\.tiff \(\[\[psf\]\] 1, 2 frames\): too few photons"):
        check_recordings(load_recordings(toml), BANDS, (2.0, math.inf), K)
