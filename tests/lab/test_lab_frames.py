"""Frame readers: each format round-trips, a raw file is binned R, G (mean), B from its own CFA pattern, and every
file that is no camera frame is refused with its name and a fix."""

import math
from pathlib import Path

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.lab.frames import (bin_bayer, expand, full_scale, mean_frames, raw_black_level, read_frame,
                              stated_white_level, write_frame)

# the CFA letters of a DNG's CFAPattern tag values (0 = red, 1 = green, 2 = blue)
_CFA = {"R": 0, "G": 1, "B": 2}


def _write_dng(path: Path, mosaic: np.ndarray, pattern: str, black=(64,), white=4095) -> Path:
    """A minimal DNG (LibRaw reads it) of a uint16 Bayer mosaic, written with tifffile's DNG tags."""
    import tifffile

    black = tuple(black)
    tags = [(50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
            (50708, "s", 0, "doefab test camera", True),  # UniqueCameraModel
            (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
            (33422, "B", 4, tuple(_CFA[c] for c in pattern), True),  # CFAPattern
            (50714, "H", len(black), black, True),  # BlackLevel
            (50717, "H", 1, (white,), True),  # WhiteLevel
            (50721, "2i", 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True)]  # ColorMatrix1
    if len(black) == 4:
        tags.append((50713, "H", 2, (2, 2), True))  # BlackLevelRepeatDim
    tifffile.imwrite(path, mosaic.astype(np.uint16), photometric=32803, extratags=tags)
    return path


@pytest.mark.parametrize("name, shape, bits, scale", [
    ("g16.tiff", (12, 10), 16, 65535), ("c16.tif", (12, 10, 3), 16, 65535), ("g16.png", (12, 10), 16, 65535),
    ("g8.png", (12, 10), 8, 255), ("c8.png", (12, 10, 3), 8, 255), ("g16.npy", (12, 10), 16, 65535)])
def test_integer_frames_round_trip(tmp_path, name, shape, bits, scale):
    rng = np.random.default_rng(1)
    a = rng.integers(0, 2**bits, shape).astype(np.float64)
    write_frame(tmp_path / name, a, bits=bits)
    got = read_frame(tmp_path / name)
    assert got.dtype == np.float64 and got.shape == shape
    np.testing.assert_array_equal(got, a)
    assert full_scale(tmp_path / name) == scale


def test_float_and_planar_tiffs(tmp_path):
    import tifffile

    a = np.random.default_rng(2).random((9, 7)).astype(np.float32)
    tifffile.imwrite(tmp_path / "norm.tiff", a)
    np.testing.assert_array_equal(read_frame(tmp_path / "norm.tiff"), a.astype(np.float64))
    assert full_scale(tmp_path / "norm.tiff") == 1.0  # a normalised float frame
    tifffile.imwrite(tmp_path / "dn.tiff", a * 3000)
    assert full_scale(tmp_path / "dn.tiff") == math.inf  # float DN: no clip level is known
    planar = np.random.default_rng(3).integers(0, 60000, (3, 8, 6)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "planar.tiff", planar, planarconfig="separate", photometric="rgb")
    np.testing.assert_array_equal(read_frame(tmp_path / "planar.tiff"), np.moveaxis(planar, 0, -1))


def test_bin_bayer_takes_each_colour_from_its_cell_position():
    mosaic = np.zeros((4, 6))
    cell = {"R": 10.0, "G1": 20.0, "G2": 40.0, "B": 70.0}
    for pattern, order in [("RGGB", ("R", "G1", "G2", "B")), ("BGGR", ("B", "G1", "G2", "R")),
                           ("GRBG", ("G1", "R", "B", "G2")), ("GBRG", ("G1", "B", "R", "G2"))]:
        mosaic[0::2, 0::2], mosaic[0::2, 1::2] = cell[order[0]], cell[order[1]]
        mosaic[1::2, 0::2], mosaic[1::2, 1::2] = cell[order[2]], cell[order[3]]
        got = bin_bayer(mosaic, pattern)
        assert got.shape == (2, 3, 3)
        np.testing.assert_array_equal(got[1, 2], [10.0, 30.0, 70.0]), pattern
    assert bin_bayer(np.ones((5, 7)), "RGGB").shape == (2, 3, 3)  # odd edges dropped
    with pytest.raises(DoefabError, match="RGGB"):
        bin_bayer(mosaic, "RGBB")


def test_dng_is_binned_by_its_own_pattern_with_its_levels(tmp_path):
    m = np.random.default_rng(4).integers(64, 4000, (64, 96))
    path = _write_dng(tmp_path / "f.dng", m, "GRBG", black=(60, 70, 80, 90), white=4095)
    got = read_frame(path)
    assert got.shape == (32, 48, 3)
    np.testing.assert_array_equal(got[..., 0], m[0::2, 1::2])  # R: row 0, column 1 of each cell
    np.testing.assert_array_equal(got[..., 1], 0.5 * (m[0::2, 0::2] + m[1::2, 1::2]))
    np.testing.assert_array_equal(got[..., 2], m[1::2, 0::2])
    assert full_scale(path) == 4095
    np.testing.assert_array_equal(raw_black_level(path), [70.0, 75.0, 80.0])  # G: mean of 60 and 90
    np.testing.assert_array_equal(raw_black_level(tmp_path / "x.tiff"), [0.0, 0.0, 0.0])


def test_unreadable_and_foreign_files_are_named_with_a_fix(tmp_path):
    (tmp_path / "cut.tiff").write_bytes(b"II*\x00garbage")
    with pytest.raises(DoefabError, match=r"cut\.tiff cannot be read as tiff .*pixel_format"):
        read_frame(tmp_path / "cut.tiff")
    (tmp_path / "bad.dng").write_bytes(b"not a raw file" * 10)
    with pytest.raises(DoefabError, match=r"bad\.dng cannot be read as raw"):
        read_frame(tmp_path / "bad.dng")
    with pytest.raises(DoefabError, match=r"frame\.jpg.*names no frame format.*\.tiff"):
        read_frame(tmp_path / "frame.jpg")
    np.save(tmp_path / "c.npy", np.ones((4, 4), complex))
    with pytest.raises(DoefabError, match=r"c\.npy holds complex128"):
        read_frame(tmp_path / "c.npy")
    np.save(tmp_path / "nan.npy", np.full((4, 4), np.nan))
    with pytest.raises(DoefabError, match=r"nan\.npy holds non-finite"):
        read_frame(tmp_path / "nan.npy")
    np.save(tmp_path / "rgba.npy", np.ones((4, 4, 4)))
    with pytest.raises(DoefabError, match=r"rgba\.npy has shape \(4, 4, 4\)"):
        read_frame(tmp_path / "rgba.npy")


def test_tiffs_with_alpha_are_refused_as_such_not_as_stacks(tmp_path):
    import tifffile

    rgb = np.random.default_rng(5).integers(0, 60000, (9, 7, 3)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "rgba.tiff", np.dstack([rgb, rgb[..., :1]]), photometric="rgb", extrasamples=[2])
    tifffile.imwrite(tmp_path / "ga.tiff", rgb[..., :2], photometric="minisblack", extrasamples=[2])
    tifffile.imwrite(tmp_path / "planar.tiff", np.moveaxis(np.dstack([rgb, rgb[..., :1]]), -1, 0),
                     photometric="rgb", planarconfig="separate", extrasamples=[2])
    for name, n in (("rgba.tiff", 4), ("ga.tiff", 2), ("planar.tiff", 4)):
        with pytest.raises(DoefabError, match=rf"{name} holds {n} samples per pixel .* without alpha") as exc:
            read_frame(tmp_path / name)
        assert "stack" not in str(exc.value)
    four = rgb[..., 0][None].repeat(4, axis=0)
    tifffile.imwrite(tmp_path / "stack.tiff", four, photometric="minisblack")  # four grey pages: a stack
    with pytest.raises(DoefabError, match=r"stack\.tiff holds a stack of 4 images"):
        read_frame(tmp_path / "stack.tiff")


def test_the_white_level_a_file_states(tmp_path):
    import tifffile

    a = np.random.default_rng(6).integers(0, 4000, (6, 5, 3))
    write_frame(tmp_path / "c16.tiff", a)
    assert stated_white_level(tmp_path / "c16.tiff") == 65535
    tifffile.imwrite(tmp_path / "norm.tiff", (a / 4095).astype(np.float32), photometric="rgb")
    assert stated_white_level(tmp_path / "norm.tiff") == 1.0
    tifffile.imwrite(tmp_path / "dn.tiff", a.astype(np.float32), photometric="rgb")
    with pytest.raises(DoefabError, match=r"dn\.tiff holds floats above 1 .* give --wl"):
        stated_white_level(tmp_path / "dn.tiff", key="--wl")
    tifffile.imwrite(tmp_path / "i32.tiff", a.astype(np.int32), photometric="rgb")
    np.save(tmp_path / "u32.npy", a.astype(np.uint32))
    for name in ("i32.tiff", "u32.npy"):  # a 12-bit camera's values in 32-bit integers: 2^31 − 1 or 2^32 − 1
        with pytest.raises(DoefabError, match=r"holds integers wider than 16 bits, whose full scale 4294967295 DN|"
                                              r"holds integers wider than 16 bits, whose full scale 2147483647 DN"):
            stated_white_level(tmp_path / name)


def test_the_widest_integer_frame_that_states_its_white_level_is_16_bits(tmp_path, monkeypatch):
    import doefab.lab.frames as frames

    write_frame(tmp_path / "c.tiff", np.zeros((4, 4, 3)))
    for top, ok in ((2.0**16 - 1, True), (2.0**17 - 1, False)):  # a 17-bit file's full scale: no sensor's level
        monkeypatch.setattr(frames, "full_scale", lambda *a, top=top, **k: top)
        if ok:
            assert stated_white_level(tmp_path / "c.tiff") == top
        else:
            with pytest.raises(DoefabError, match="wider than 16 bits, whose full scale 131071 DN"):
                stated_white_level(tmp_path / "c.tiff")


def test_16_bit_colour_png_is_refused_not_truncated(tmp_path):
    import struct
    import zlib

    h, w = 4, 5
    rows = b"".join(b"\x00" + np.full((w, 3), 40000, ">u2").tobytes() for _ in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))
    (tmp_path / "c16.png").write_bytes(png)
    with pytest.raises(DoefabError, match=r"c16\.png is a 16-bit colour PNG.*TIFF"):
        read_frame(tmp_path / "c16.png")


def test_mean_frames_and_size_mismatch(tmp_path):
    write_frame(tmp_path / "a_1.tiff", np.full((6, 8), 10.0))
    write_frame(tmp_path / "a_2.tiff", np.full((6, 8), 30.0))
    mean, n = mean_frames(expand("a_*.tiff", tmp_path, "frames"))
    assert n == 2 and np.all(mean == 20.0)
    write_frame(tmp_path / "a_3.tiff", np.full((6, 9), 30.0))
    with pytest.raises(DoefabError, match=r"a_3\.tiff is 9×6 px but .*a_1\.tiff is 8×6 px"):
        mean_frames(expand(["a_*.tiff"], tmp_path, "frames"))


def test_expand_globs_relative_to_base_and_names_an_empty_pattern(tmp_path):
    (tmp_path / "psf").mkdir()
    for name in ("f_2.npy", "f_1.npy", "other.npy"):
        np.save(tmp_path / "psf" / name, np.zeros((2, 2)))
    got = expand(["psf/f_*.npy", "psf/f_1.npy"], tmp_path, "[[psf]] 1 frames")
    assert got == [tmp_path / "psf" / "f_1.npy", tmp_path / "psf" / "f_2.npy"]
    with pytest.raises(DoefabError, match=r"\[\[psf\]\] 1 frames: no file matches 'dark/\*\.npy'"):
        expand("dark/*.npy", tmp_path, "[[psf]] 1 frames")


def test_write_frame_refuses_values_that_do_not_fit(tmp_path):
    with pytest.raises(DoefabError, match="0 … 255 DN"):
        write_frame(tmp_path / "x.png", np.full((3, 3), 300.0), bits=8)
    assert not (tmp_path / "x.png").exists()


def test_a_dng_read_as_a_tiff_or_cut_short_gets_one_clear_error(tmp_path, capfd):
    """A DNG is a TIFF container: read as a TIFF it would give the raw mosaic without its levels, so that is
    refused naming the raw reader; a DNG that ends early is refused once, in our words (LibRaw's own message on
    the C stderr goes into ours, not to the terminal)."""
    m = np.full((64, 64), 1000, np.uint16)
    path = _write_dng(tmp_path / "f.dng", m, "RGGB")
    with pytest.raises(DoefabError, match=r"f\.dng is a DNG .* set pixel_format to \"raw\""):
        read_frame(path, "tiff")
    data = path.read_bytes()
    (tmp_path / "cut.dng").write_bytes(data[: len(data) - 4000])
    capfd.readouterr()
    with pytest.raises(DoefabError, match=r"cut\.dng cannot be read as raw \(LibRaw: .*complete camera raw"):
        read_frame(tmp_path / "cut.dng")
    assert capfd.readouterr().err == ""
    assert read_frame(path).shape == (32, 32, 3)  # the whole file reads
