"""The reconstruction writers (doefab.lab.outputs): each file read back with its own library and compared with
what was written, the previews against independent colour science, and atomic writes."""

from __future__ import annotations

import os

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.lab import outputs as O


def _rgb(h=24, w=32, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 2, (3, h, w)).astype(np.float32)
    x[:, 5, 7] = 200.0  # a white highlight, far above the clipping level 1
    return x


def test_exr_reads_back_as_half_float_rgb(tmp_path):
    import OpenEXR

    x = _rgb()
    p = O.write_hdr_exr(tmp_path / "a.exr", x)
    with OpenEXR.File(str(p)) as f:
        ch = f.channels()
        assert list(ch) == ["RGB"]
        back = np.moveaxis(ch["RGB"].pixels, -1, 0)
    assert back.dtype == np.float16 and back.shape == x.shape
    # half float: 11 significant bits, so a value rounds to within 2^-11 of itself (relative; 2^-25 near 0)
    assert np.all(np.abs(back.astype(np.float64) - x) <= np.maximum(np.abs(x) * 2.0**-11, 2.0**-25))
    assert os.listdir(tmp_path) == ["a.exr"]  # no temporary file left


def test_exr_refuses_what_half_float_cannot_hold_and_writes_nothing(tmp_path):
    for bad, needle in ((np.full((3, 4, 4), -1.0), "0 … 65504"), (np.full((3, 4, 4), 1e5), "0 … 65504"),
                        (np.zeros((4, 4)), r"\[3, H, W\]"), (np.full((3, 4, 4), np.nan), "NaN")):
        with pytest.raises(DoefabError, match=needle):
            O.write_hdr_exr(tmp_path / "a.exr", bad)
    assert os.listdir(tmp_path) == []


def test_reinhard_maps_the_brightest_to_white_and_keeps_each_pixels_colour():
    x = _rgb()
    y = O.reinhard(x)
    lum = np.tensordot(O.REC709_LUMA, y, axes=1)
    assert np.isclose(lum[5, 7], 1.0) and lum.max() <= 1.0 + 1e-12  # L_white = the largest scaled luminance → 1
    ratio = y / x  # one factor per pixel (hue kept) where nothing clips
    ok = (y < 1).all(axis=0)
    np.testing.assert_allclose(ratio[0][ok], ratio[1][ok], rtol=1e-9)
    # Reinhard et al. (2002) eq. 1-4 at one pixel, by hand
    lum_x = np.tensordot(O.REC709_LUMA, x.astype(np.float64), axes=1)
    key = 0.18 / np.exp(np.mean(np.log(1e-6 + lum_x)))
    ls, lw = key * lum_x[0, 0], key * lum_x.max()
    assert np.isclose(lum[0, 0], ls * (1 + ls / lw**2) / (1 + ls))


def test_srgb_encoding_at_known_points():
    # IEC 61966-2-1: 0 → 0, 1 → 1, the linear segment below 0.0031308, 0.5 → 0.7354 (188 of 255), 0.18 → 0.4614
    np.testing.assert_allclose(O.srgb_encode([0.0, 1.0, 0.002, 0.5, 0.18]),
                               [0.0, 1.0, 0.02584, 0.735357, 0.461356], atol=1e-5)


def test_tonemapped_png_is_8_bit_rgb_of_the_operator(tmp_path):
    """600 rows: written in bands of 256 rows, with the whole image's log-average and white point."""
    import imageio.v3 as iio

    x = _rgb(600, 8)
    x[:, 500:] *= 0.01  # a dark lower part: a band's own statistics would differ from the image's
    back = iio.imread(O.write_tonemapped_png(tmp_path / "a.png", x))
    assert back.dtype == np.uint8 and back.shape == (600, 8, 3)
    want = np.rint(np.moveaxis(O.srgb_encode(O.reinhard(x)), 0, -1) * 255)
    assert np.abs(back.astype(float) - want).max() <= 0


def test_envi_reads_back_with_its_wavelengths_in_nm(tmp_path):
    import spectral

    wl = np.linspace(401.25e-9, 698.5e-9, 31)  # not whole nanometres: the header keeps them
    cube = np.random.default_rng(1).uniform(0, 1, (31, 12, 20)).astype(np.float32)
    hdr = O.write_envi(tmp_path / "s.hdr", cube, wl)
    assert sorted(os.listdir(tmp_path)) == ["s.hdr", "s.img"]
    img = spectral.open_image(str(hdr))
    assert img.shape == (12, 20, 31) and img.bands.band_unit == "nm"
    np.testing.assert_allclose(img.bands.centers, wl * 1e9, rtol=0, atol=5e-4)  # nm, to 6 significant digits
    assert np.array_equal(np.moveaxis(img.load(), -1, 0), cube)  # float32, bit for bit
    with pytest.raises(DoefabError, match="one wavelength in metres per band"):
        O.write_envi(tmp_path / "t.hdr", cube, wl[:30])
    with pytest.raises(DoefabError, match="ending in .hdr"):
        O.write_envi(tmp_path / "t.img", cube, wl)
    assert sorted(os.listdir(tmp_path)) == ["s.hdr", "s.img"]


def test_srgb_preview_of_daylight_is_neutral_and_of_red_light_is_red(tmp_path):
    """CIE D65's own spectrum is the sRGB white: equal R, G, B (colour-science's D65 table, independent of the
    writer's CMF weighting); a 620 nm band alone is red."""
    import colour
    import imageio.v3 as iio

    wl = np.arange(400, 701, 10) * 1e-9
    d65 = colour.SDS_ILLUMINANTS["D65"]
    spd = np.interp(wl * 1e9, d65.wavelengths, d65.values)
    cube = spd[:, None, None] * np.array([[1.0, 0.5]])[None]  # one white pixel, one at half the light
    back = iio.imread(O.write_srgb_preview(tmp_path / "p.png", cube, wl, percentile=100)).astype(int)
    assert back.shape == (1, 2, 3) and np.all(back[0, 0] >= 253)
    assert np.ptp(back[0, 1]) <= 2 and 180 <= back[0, 1, 0] <= 195  # sRGB of 0.5: 188
    red = np.zeros((31, 1, 1))
    red[22] = 1.0  # 620 nm
    r, g, b = iio.imread(O.write_srgb_preview(tmp_path / "r.png", red, wl))[0, 0].astype(int)
    assert r > 200 and g < r / 2 and b < 30


def test_depth_tiff_is_float32_metres(tmp_path):
    import tifffile

    d = np.random.default_rng(2).uniform(0.5, 6.0, (20, 30))
    back = tifffile.imread(O.write_depth_tiff(tmp_path / "d.tiff", d))
    assert back.dtype == np.float32 and np.array_equal(back, d.astype(np.float32))


def test_depth_png16_is_millimetres_rounded_and_clipped_at_65_535_m(tmp_path):
    import imageio.v3 as iio

    d = np.random.default_rng(3).uniform(0.0, 6.0, (20, 30))
    d[0, 0], d[0, 1] = 70.0, 65.535
    back = iio.imread(O.write_depth_png16(tmp_path / "d.png", d))
    assert back.dtype == np.uint16 and back.shape == d.shape
    ok = d <= O.MAX_DEPTH_PNG_M
    assert np.abs(back[ok] / 1000.0 - d[ok]).max() <= 0.0005 + 1e-12  # rounded to the millimetre
    assert back[0, 0] == 65535 and back[0, 1] == 65535
    with pytest.raises(DoefabError, match="negative depths"):
        O.write_depth_png16(tmp_path / "e.png", -d)


def test_depth_preview_runs_from_near_to_far_through_viridis(tmp_path):
    import imageio.v3 as iio
    from matplotlib import colormaps

    d = np.array([[1.0, 3.0, 5.0, 9.0]])
    back = iio.imread(O.write_depth_preview(tmp_path / "p.png", d, near_m=1.0, far_m=5.0)).astype(int)
    want = np.rint(np.asarray(colormaps["viridis"]([0.0, 0.5, 1.0, 1.0]))[:, :3] * 255)
    assert np.abs(back[0] - want).max() <= 1


def test_a_failed_write_leaves_neither_the_file_nor_a_temporary(tmp_path, monkeypatch):
    import tifffile

    def broken(path, *a, **k):
        with open(path, "wb") as fh:
            fh.write(b"II*\0half a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(tifffile, "imwrite", broken)
    with pytest.raises(OSError):
        O.write_depth_tiff(tmp_path / "d.tiff", np.ones((4, 4)))
    assert os.listdir(tmp_path) == []


def test_write_result_writes_each_tasks_files(tmp_path):
    wl = np.linspace(400e-9, 700e-9, 31)
    files = O.write_result("depth", np.full((8, 8), 2.0), tmp_path / "d", "x", depth_range_m=(1.0, 5.0))
    assert [f.name for f in files] == ["x.depth_m.tiff", "x.depth_mm.png", "x.png"]
    files = O.write_result("hyperspectral", np.ones((31, 8, 8)), tmp_path / "s", "x", wavelengths_m=wl)
    assert sorted(os.listdir(tmp_path / "s")) == ["x.hdr", "x.img", "x.png"] and files[0].name == "x.hdr"
    O.write_result("hdr", np.ones((3, 8, 8)), tmp_path / "h", "x")
    assert sorted(os.listdir(tmp_path / "h")) == ["x.exr", "x.png"]


def test_envi_written_row_block_by_row_block_is_the_cube(tmp_path):
    import spectral

    wl = np.linspace(400e-9, 700e-9, 31)
    cube = np.random.default_rng(4).uniform(0, 1, (31, 10, 7)).astype(np.float32)
    blocks = [(0, cube[:, :4]), (4, cube[:, 4:9]), (9, cube[:, 9:])]
    img = spectral.open_image(str(O.write_envi_rows(tmp_path / "s.hdr", iter(blocks), cube.shape, wl)))
    assert np.array_equal(np.moveaxis(img.load(), -1, 0), cube)
    with pytest.raises(DoefabError, match="got 9 of its 10 rows"):
        O.write_envi_rows(tmp_path / "t.hdr", iter(blocks[:2]), cube.shape, wl)
    with pytest.raises(DoefabError, match="do not continue"):
        O.write_envi_rows(tmp_path / "t.hdr", iter([blocks[1]]), cube.shape, wl)
    assert sorted(os.listdir(tmp_path)) == ["s.hdr", "s.img"]  # a failed cube leaves nothing


@pytest.mark.parametrize("task, shape", [("hyperspectral", (31, 10, 7)), ("depth", (1, 10, 7)), ("hdr", (3, 10, 7))])
def test_rows_give_the_files_the_whole_result_gives(task, shape, tmp_path):
    wl = np.linspace(400e-9, 700e-9, 31)
    res = np.random.default_rng(5).uniform(0.5, 2, shape).astype(np.float32)
    whole = O.write_result(task, res[0] if task == "depth" else res, tmp_path / "a", "x", wl, (0.5, 2.0))
    rows = O.write_result_rows(task, iter([(0, res[:, :3]), (3, res[:, 3:])]), shape, tmp_path / "b", "x", wl,
                               (0.5, 2.0))
    assert [p.name for p in whole] == [p.name for p in rows]
    for a, b in zip(whole, rows):
        assert a.read_bytes() == b.read_bytes(), a.name
