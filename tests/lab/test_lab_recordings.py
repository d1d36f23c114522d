"""The recordings file: its schema refused key by key, and every frame problem a calibration could not use named
with its file and its fix, all of them in one error; good recordings pass."""

import math
import re

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.lab.framechecks import MIN_KERNEL_SNR, psf_signal
from doefab.lab.frames import write_frame
from doefab.lab.recordings import (band_index, check_recordings, load_recordings, plane_index, recording_problems,
                                   recordings_sha256)

BANDS = (450e-9, 550e-9, 650e-9)
PLANES = (2.0, math.inf)
K = 31
BLACK = 64.0


def _spot(size=64, photons=2e5, sigma=2.0, centre=(30.3, 33.6)):
    y, x = np.mgrid[:size, :size]
    g = np.exp(-((y - centre[0]) ** 2 + (x - centre[1]) ** 2) / (2 * sigma**2))
    return photons * g / g.sum()


def _frames(folder, name, expected, n=4, read=2.0, seed=0):
    """``n`` frames (gain 1 e/DN, black level 64 DN) of ``expected`` electrons, shot and read noise."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        e = rng.poisson(expected) + rng.normal(0, read, expected.shape) + BLACK
        write_frame(folder / f"{name}_{i}.tiff", np.clip(np.rint(e), 0, 65535))


def _write(folder, body: str):
    (folder / "rec.toml").write_text('pixel_format = "auto"\nblack_level = 64\n' + body)
    return folder / "rec.toml"


PSF = """
[[psf]]
half = "coded"
view = "coded"
depth_m = {depth}
{source}
frames = ["{frames}_*.tiff"]
{dark}
"""


def _psf(frames="psf/f", depth="2.0", source="wavelength_nm = 550", dark='dark = ["psf/dark_*.tiff"]'):
    return PSF.format(frames=frames, depth=depth, source=source, dark=dark)


@pytest.fixture
def lab(tmp_path):
    (tmp_path / "psf").mkdir()
    _frames(tmp_path / "psf", "f", _spot())
    _frames(tmp_path / "psf", "dark", np.zeros((64, 64)), n=2, seed=1)
    return tmp_path


def test_good_recordings_pass_and_their_light_is_measured(lab):
    rec = load_recordings(_write(lab, _psf() + _psf(depth='"inf"', dark="")))
    assert [r.depth_m for r in rec.psf] == [2.0, math.inf] and rec.psf[0].wavelength_m == pytest.approx(550e-9)
    assert rec.psf[0].frames == sorted((lab / "psf").glob("f_*.tiff")) and len(rec.psf[0].dark) == 2
    assert recording_problems(rec, BANDS, PLANES, K) == []
    check_recordings(rec, BANDS, PLANES, K)
    got = psf_signal(rec, rec.psf[0], K)
    assert got.total[0] == pytest.approx(2e5, rel=0.01)  # the spot's electrons (gain 1), all in the window
    # the sum's noise: shot noise and read noise (2 e) of 4 frames, read noise of the 2 darks' mean
    sigma = math.sqrt((2e5 + K * K * 4.0) / 4 + K * K * 4.0 / 2)
    assert got.kernel_snr[0] == pytest.approx(2e5 / sigma, rel=0.15)
    assert abs(got.peak[0] - 30) <= 1 and abs(got.peak[1] - 34) <= 1


def test_schema_problems_are_listed_together_with_their_keys(tmp_path):
    body = """
colour = "yes"
black_level = -3
[[psf]]
half = "left"
view = "coded"
depth_m = 0
wavelength_nm = 550
channels = "rgb"
frames = ["missing_*.tiff"]
exposure = 0.1
[[wall]]
half = "plain"
coded_view = "w/c.tiff"
"""
    (tmp_path / "rec.toml").write_text(body)
    with pytest.raises(DoefabError) as exc:
        load_recordings(tmp_path / "rec.toml")
    msg = str(exc.value)
    for part in ("colour is not a key of the recordings file: the keys are design, pixel_format, black_level, "
                 "white_level, psf, wall",
                 "black_level = -3 must be a finite number ≥ 0 (DN)",
                 "[[psf]] 1 half = 'left' is not one of 'coded', 'plain'",
                 "[[psf]] 1 depth_m = 0 must be a distance > 0 in metres, or \"inf\"",
                 "[[psf]] 1 wavelength_nm and channels: give exactly one",
                 "[[psf]] 1 frames: no file matches 'missing_*.tiff'",
                 "[[psf]] 1 exposure is not a key of [[psf]]: the keys are half, view, depth_m, wavelength_nm",
                 "[[wall]] 1 coded_view: no file matches 'w/c.tiff'",
                 "[[wall]] 1 plain_view is missing"):
        assert part in msg, part
    assert msg.count("\n  - ") == 9


def test_wavelength_in_metres_gets_the_unit_hint_and_design_is_resolved(lab, tmp_path):
    with pytest.raises(DoefabError, match=r"wavelength_nm = 5.5e-07 .*550 nm"):
        load_recordings(_write(lab, _psf(source="wavelength_nm = 5.5e-7")))
    with pytest.raises(DoefabError, match=r"\[\[psf\]\] 1 wavelength_nm and channels: give exactly one"):
        load_recordings(_write(lab, _psf(source="")))
    with pytest.raises(DoefabError, match=r"design: .*nowhere is not a design folder .*--design"):
        load_recordings(_write(lab, 'design = "nowhere"\n' + _psf()))
    (lab / "d").mkdir()
    (lab / "d" / "design.json").write_text("{}")
    assert load_recordings(_write(lab, 'design = "d"\n' + _psf())).design == lab / "d"
    assert load_recordings(_write(lab, _psf()), design=lab / "d").design == lab / "d"


def test_a_committed_design_by_name_is_the_shipped_one_unless_a_folder_of_that_name_is_there(lab, tmp_path,
                                                                                            monkeypatch):
    from doefab.design.committed import committed_dir

    elsewhere = tmp_path / "elsewhere"  # run from a folder that holds an unrelated half-ring/: beside the file decides
    (elsewhere / "half-ring").mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    got = load_recordings(_write(lab, 'design = "half-ring"\n' + _psf())).design
    assert got == committed_dir("half-ring") and (got / "design.json").is_file()
    assert load_recordings(_write(lab, 'design = "masks/half-ring"\n' + _psf())).design == got
    (lab / "half-ring").mkdir()
    (lab / "half-ring" / "design.json").write_text("{}")  # the lab's own folder of that name wins
    assert load_recordings(_write(lab, 'design = "half-ring"\n' + _psf())).design == lab / "half-ring"


def test_a_folder_of_designs_given_as_the_design_names_them(lab):
    for name in ("set_b", "set_a"):
        (lab / "masks" / name / "design").mkdir(parents=True)
        (lab / "masks" / name / "design" / "design.json").write_text("{}")
    with pytest.raises(DoefabError, match=r"masks is not a design folder .*; it holds set_a, set_b: give one of them"):
        load_recordings(_write(lab, _psf()), design=lab / "masks")


def _problems(lab, body, bands=BANDS, planes=PLANES, kernel=K):
    rec = load_recordings(_write(lab, body))
    before = sorted(p.name for p in lab.rglob("*"))
    with pytest.raises(DoefabError) as exc:
        check_recordings(rec, bands, planes, kernel)
    assert sorted(p.name for p in lab.rglob("*")) == before  # nothing written
    return str(exc.value)


def test_each_frame_problem_names_its_file_and_fix(lab):
    psf = lab / "psf"
    (psf / "cut_0.tiff").write_bytes(b"II*\x00broken")
    write_frame(psf / "cut_1.tiff", np.full((64, 64), 70.0))
    write_frame(psf / "cut_2.tiff", np.full((60, 64), 70.0))  # a problem after an unreadable file is found too
    _frames(psf, "size", _spot(), n=2)
    write_frame(psf / "size_9.tiff", np.full((64, 60), 70.0))
    _frames(psf, "dark40", np.zeros((40, 40)), n=2)
    _frames(psf, "sat", _spot(photons=4e7), n=2)
    _frames(psf, "dim", _spot(photons=300.0), n=4)
    _frames(psf, "small", _spot(size=24, centre=(12, 12)), n=2)
    _frames(psf, "hot", np.full((64, 64), 256.0 * 64), n=2)  # a 16-bit dark under frames saved 8-bit (÷ 256)
    for i in range(4):
        write_frame(psf / f"eight_{i}.tiff", np.rint((_spot() + 64) / 256))
    _frames(psf, "ped", _spot() + 60.0, n=2)  # 60 DN of pedestal more than the darks hold (a black level left in)
    _frames(psf, "over", _spot(photons=1e6), n=2)
    _frames(psf, "hidark", np.full((64, 64), 60.0), n=2, seed=3)  # darks 60 DN above the frames' black level
    msg = _problems(lab, _psf("psf/cut") + _psf("psf/size") + _psf(dark='dark = ["psf/dark40_*.tiff"]')
                    + _psf("psf/sat") + _psf("psf/dim") + _psf("psf/small", dark="")
                    + _psf("psf/eight", dark='dark = ["psf/hot_*.tiff"]') + _psf("psf/ped")
                    + _psf("psf/over", dark='dark = ["psf/hidark_*.tiff"]'))
    assert "cut_0.tiff cannot be read as tiff" in msg and "cut_2.tiff is 64×60 px but" in msg
    assert "size_9.tiff is 60×64 px but" in msg and "must have the same size" in msg
    assert "dark40_0.tiff is 40×40 px but [[psf]] 3's frames" in msg and "record the dark frames at the frames' size" \
        in msg
    assert "sat_0.tiff: its brightest pixel" in msg and "reduce the exposure or the source power" in msg
    assert "sat_1.tiff" in msg  # every saturated frame, not the first only
    assert f"dim_0.tiff ([[psf]] 5, 4 frames): too few photons for the {K}×{K}-px kernel" in msg
    assert f"needs ≥ {MIN_KERNEL_SNR:g}" in msg and "record more light" in msg
    assert f"small_0.tiff: [[psf]] 6's frames are 24×24 px, smaller than the design's {K}×{K}-px kernel" in msg
    assert "eight_0.tiff ([[psf]] 7): its dark frames' mean (" in msg
    assert "hot_0.tiff), 1.645e+04 DN, is no darker" in msg
    assert "too few photons" not in msg.split("eight_0.tiff")[1]  # not "record more light" for a negative signal
    assert re.search(r"ped_0\.tiff \(\[\[psf\]\] 8\): the frame's border, far from the spot, reads 60(\.5)? DN above "
                     r"zero once its dark frames are subtracted", msg) and "recorded with the source off" in msg
    assert re.search(r"over_0\.tiff \(\[\[psf\]\] 9\): the frame's border, far from the spot, reads 60(\.5)? DN below "
                     r"zero .* taken from the light", msg)
    assert msg.count("\n  - ") == 11  # one per problem, every recording checked


def test_frames_that_state_no_clip_level_ask_for_white_level_once_a_set(lab):
    import tifffile

    for i in range(3):  # the saturation check needs the sensor's clip level, which these files do not state
        tifffile.imwrite(lab / "psf" / f"wide_{i}.tiff", np.rint(_spot() + BLACK).astype(np.int32))
        tifffile.imwrite(lab / "psf" / f"fdn_{i}.tiff", (_spot() + BLACK).astype(np.float32))
    msg = _problems(lab, _psf("psf/wide") + _psf("psf/fdn"))
    assert "wide_0.tiff holds integers wider than 16 bits" in msg and "fdn_0.tiff holds floats above 1" in msg
    assert msg.count("give the recordings file's white_level") == 2  # once per set of frames, not per frame
    rec = load_recordings(_write(lab, "white_level = 65535\n" + _psf("psf/wide") + _psf("psf/fdn")))
    assert recording_problems(rec, BANDS, PLANES, K) == []


def test_wavelengths_depths_and_channels_the_design_cannot_use(lab):
    _frames(lab / "psf", "rgb", np.stack([_spot()] * 3, axis=-1), n=2)
    body = (_psf(source="wavelength_nm = 552") + _psf(depth="2.05") + _psf(depth='"inf"')
            + _psf("psf/rgb", source='channels = "rgb"', dark="") + _psf("psf/f", source='channels = "rgb"')
            + _psf(depth="5000"))
    msg = _problems(lab, body, bands=(450e-9, 550e-9), planes=(2.0, 5.0))
    assert "[[psf]] 1 wavelength_nm = 552 is no band of the design (within 1 nm): record at one of 450, 550 nm" in msg
    assert "[[psf]] 2 depth_m = 2.05 is no plane of the design (within 1%): place the source at one of 2, 5 m" in msg
    assert "[[psf]] 3 depth_m = inf is no plane of the design (within 1%):" in msg  # no unit hint for inf
    assert "[[psf]] 6 depth_m = 5000 is no plane of the design (within 1%) (depth_m is in metres: 5?): place" in msg
    assert "[[psf]] 4 channels = \"rgb\": one PSF per colour channel needs a 3-band design, this design has 2" in msg
    assert "f_0.tiff: [[psf]] 5 has channels = \"rgb\" but its frames are monochrome" in msg
    assert load_recordings(_write(lab, _psf("psf/rgb", source='channels = "rgb"', dark=""))) is not None
    rgb = load_recordings(_write(lab, _psf("psf/rgb", source='channels = "rgb"', dark="")))
    assert recording_problems(rgb, BANDS, PLANES, K) == []  # a broadband recording of a 3-band design
    narrow = load_recordings(_write(lab, _psf("psf/rgb", dark="")))
    assert "is a narrow-band recording (wavelength_nm) but its frames are colour" in \
        recording_problems(narrow, BANDS, PLANES, K)[0]


def test_wall_views_of_different_sizes(lab):
    (lab / "w").mkdir()
    _frames(lab / "w", "c", np.full((64, 64), 3e4), n=2)
    _frames(lab / "w", "p", np.full((64, 62), 1e3), n=2)
    _frames(lab / "w", "s", np.full((64, 64), 66000.0), n=1)
    body = ('[[wall]]\nhalf = "coded"\ncoded_view = "w/c_*.tiff"\nplain_view = "w/p_*.tiff"\n'
            '[[wall]]\nhalf = "plain"\ncoded_view = "w/c_*.tiff"\nplain_view = "w/s_*.tiff"\n')
    msg = _problems(lab, body)
    assert "p_0.tiff (plain view) is 62×64 px but" in msg and "[[wall]] 1's two views must be of one capture" in msg
    assert "s_0.tiff: its brightest pixel" in msg and "reduce the exposure or the wall's illumination" in msg


def test_band_and_plane_tolerances():
    assert band_index(550.9e-9, BANDS) == 1 and band_index(551.1e-9, BANDS) is None
    assert plane_index(2.019, PLANES) == 0 and plane_index(2.021, PLANES) is None
    assert plane_index(math.inf, PLANES) == 1 and plane_index(1e6, PLANES) is None


def test_sha256_covers_every_frame(lab):
    rec = load_recordings(_write(lab, _psf()))
    first = recordings_sha256(rec)
    assert recordings_sha256(load_recordings(_write(lab, _psf()))) == first
    dark = lab / "psf" / "dark_1.tiff"
    data = bytearray(dark.read_bytes())
    data[-1] ^= 1
    dark.write_bytes(bytes(data))
    assert recordings_sha256(rec) != first


def _raw_spot(folder, name, pattern="RGGB", black=(2000, 2048, 2049, 2100), photons=2e5, n=2, clip=None,
              clip_dn=65535):
    """``n`` DNG frames (16-bit, white level 65535) of a grey spot binned to 64 × 64, each photosite on its own
    black level (``black`` per site of the 2×2 cell, row by row), with read noise 2 DN; ``clip``: one green
    photosite of the spot set to the white level."""
    from test_lab_frames import _write_dng

    rng = np.random.default_rng(5)
    spot = np.kron(_spot(photons=photons), np.ones((2, 2)))
    site = np.tile(np.asarray(black, np.float64).reshape(2, 2), (64, 64))
    for i in range(n):
        m = np.clip(np.rint(spot + site + rng.normal(0, 2.0, spot.shape)), 0, 65535)
        if clip is not None:
            m[clip] = clip_dn
        _write_dng(folder / f"{name}_{i}.dng", m, pattern, black=black, white=65535)


def test_raw_frames_without_darks_subtract_each_channels_own_black_level(tmp_path):
    """A raw whose channels sit on 2000, 2048.5 and 2100 DN, with no dark frames and no black_level: each
    channel's own level comes off (the border reads zero in all three, the spot's light is whole); one black_level
    for all three (the green's) leaves red 48.5 DN below zero and blue 51.5 above — offsets whose mean over the
    channels is 1 DN — and is refused for the red channel."""
    (tmp_path / "psf").mkdir()
    _raw_spot(tmp_path / "psf", "f")
    body = _psf("psf/f", source='channels = "rgb"', dark="").replace("_*.tiff", "_*.dng")
    (tmp_path / "rec.toml").write_text('pixel_format = "auto"\n' + body)
    rec = load_recordings(tmp_path / "rec.toml")
    assert recording_problems(rec, BANDS, PLANES, K) == []
    got = psf_signal(rec, rec.psf[0], K)
    border = np.concatenate([got.signal[:3].reshape(-1, 3), got.signal[-3:].reshape(-1, 3)])
    np.testing.assert_allclose(np.median(border, axis=0), 0.0, atol=1.0)
    np.testing.assert_allclose(got.total, 2e5, rtol=0.02)  # every photosite of a cell saw the spot
    (tmp_path / "rec.toml").write_text('pixel_format = "auto"\nblack_level = 2048.5\n' + body)
    problems = recording_problems(load_recordings(tmp_path / "rec.toml"), BANDS, PLANES, K)
    assert len(problems) == 1
    assert "(red): the frame's border, far from the spot, reads 48.5 DN below zero" in problems[0]


def test_a_raw_photosite_at_its_white_level_is_clipped_though_its_binned_pixel_is_not(tmp_path):
    """One green photosite of the spot at the white level: binned with the other green it reads about half of
    full scale, yet the frame is refused as clipped, by its photosites."""
    (tmp_path / "psf").mkdir()
    _raw_spot(tmp_path / "psf", "f", clip=(61, 66))  # row 61, column 66: a green site of the RGGB cell (30, 33)
    body = _psf("psf/f", source='channels = "rgb"', dark="").replace("_*.tiff", "_*.dng")
    (tmp_path / "rec.toml").write_text('pixel_format = "auto"\n' + body)
    problems = recording_problems(load_recordings(tmp_path / "rec.toml"), BANDS, PLANES, K)
    assert any("f_0.dng: 1 of its binned pixels hold a photosite at 98% or more" in p for p in problems)
    assert any("f_1.dng: 1 of its binned pixels" in p for p in problems)
    _raw_spot(tmp_path / "psf", "f", clip=(61, 66), clip_dn=40000)  # below the raw's white level, above a stated one
    assert not any("binned pixels" in p for p in recording_problems(load_recordings(tmp_path / "rec.toml"), BANDS,
                                                                    PLANES, K))
    (tmp_path / "rec.toml").write_text('pixel_format = "auto"\nwhite_level = 40000\n' + body)
    problems = recording_problems(load_recordings(tmp_path / "rec.toml"), BANDS, PLANES, K)
    assert any("f_0.dng: 1 of its binned pixels hold a photosite at 98% or more of white_level" in p for p in problems)


def test_a_wall_left_unlit_names_its_files(lab):
    """A wall pair with pixels that get no light once the dark is subtracted (its exposure below the dark's
    level) is refused naming the wall, the count of unlit pixels and the fix."""
    from doefab.lab.calibrate import measure_walls

    (lab / "w").mkdir()
    _frames(lab / "w", "lit", np.full((64, 64), 3e3), n=2)
    _frames(lab / "w", "dim", np.full((64, 64), 0.0), n=2, read=0.0)
    body = ('[[wall]]\nhalf = "coded"\ncoded_view = "w/lit_*.tiff"\nplain_view = "w/lit_*.tiff"\n'
            '[[wall]]\nhalf = "plain"\ncoded_view = "w/dim_*.tiff"\nplain_view = "w/dim_*.tiff"\n')
    with pytest.raises(DoefabError) as got:
        measure_walls(load_recordings(_write(lab, body)))
    msg = str(got.value)
    assert "[[wall]] 2 (half = 'plain' open): 4096 of 4096 pixels get no light" in msg and "dim_0.tiff" in msg
    assert "expose the white wall longer" in msg
    _frames(lab / "w", "leak", np.full((64, 64), 300.0), n=2)  # the open half's light leaking into the other view
    lit = ('[[wall]]\nhalf = "coded"\ncoded_view = "w/lit_*.tiff"\nplain_view = "w/leak_*.tiff"\n'
           '[[wall]]\nhalf = "plain"\ncoded_view = "w/leak_*.tiff"\nplain_view = "w/lit_*.tiff"\n')
    assert measure_walls(load_recordings(_write(lab, lit)))["alpha_lr"] == pytest.approx(300 / 3300, abs=0.01)
    same = ('[[wall]]\nhalf = "coded"\ncoded_view = "w/lit_*.tiff"\nplain_view = "w/lit_*.tiff"\n'
            '[[wall]]\nhalf = "plain"\ncoded_view = "w/lit_*.tiff"\nplain_view = "w/lit_*.tiff"\n')
    with pytest.raises(DoefabError, match=r"\[\[wall\]\] pairs' alpha_lr, alpha_rl = \(0\.5\d*, 0\.5\d*\) at column "
                                          r"\d+ is no dual-pixel crosstalk"):  # the other half never blocked
        measure_walls(load_recordings(_write(lab, same)))


def test_white_level_is_the_sensors_clip(lab):
    """A 12-bit sensor's frames in 16-bit TIFFs: a peak at its 4095 DN clip passes the file's full scale (65535)
    unnoticed, and is refused once the file states white_level = 4095; a white level at or below the black level
    is refused with its key."""
    spot = _spot(photons=2e5)
    _frames(lab / "psf", "clip", np.minimum(spot * (4095 - BLACK) / spot.max(), 4095 - BLACK), n=3)
    body = _psf("psf/clip")
    with_white = lab / "white.toml"
    with_white.write_text('pixel_format = "auto"\nblack_level = 64\nwhite_level = 4095\n' + body)
    assert "brightest pixel" not in "; ".join(recording_problems(load_recordings(_write(lab, body)), BANDS, PLANES, K))
    got = "; ".join(recording_problems(load_recordings(with_white), BANDS, PLANES, K))
    assert "clip_0.tiff: its brightest pixel" in got and "of white_level (4095 DN)" in got
    with_white.write_text('black_level = 64\nwhite_level = 64\n' + body)
    with pytest.raises(DoefabError, match="white_level = 64 DN must be above black_level"):
        load_recordings(with_white)
