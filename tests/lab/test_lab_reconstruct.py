"""Tiled reconstruction (doefab.lab.reconstruct): the tiles and their blend, the shipped networks' tiled results
against their whole-image results, reading and scaling a camera's frames, and the calibrated crosstalk unmix."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError
from doefab.lab import reconstruct as R
from doefab.lab.frames import write_frame


class LocalNet:
    """A stand-in network whose output at a pixel is the 5×5 mean of ``coded + 2·uncoded`` around it (edge
    replicated at its input's borders): it reads only 2 px around a pixel, so a tile's result equals the
    whole image's wherever the pixel lies ≥ 2 px inside the tile."""

    task, variant, model = "hdr", "proposed", None
    pair = SimpleNamespace(coded=np.zeros((1, 3, 31, 31)), wavelengths=(6.5e-7, 5.5e-7, 4.5e-7))

    def _psf(self, psf):
        return None

    def __call__(self, coded, uncoded, psf=None):
        x = coded + 2.0 * uncoded
        h, w = x.shape[1:]
        p = np.pad(x, ((0, 0), (2, 2), (2, 2)), mode="edge")
        return sum(p[:, i:i + h, j:j + w] for i in range(5) for j in range(5)) / 25.0


def _views(h, w, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(0, 1, (3, h, w)).astype(np.float32), rng.uniform(0, 1, (3, h, w)).astype(np.float32))


def _whole(rec, coded, uncoded):
    """The network on the whole image, extended at the bottom and right to multiples of 32 as the tiling is."""
    h, w = coded.shape[1:]
    pad = ((0, 0), (0, -h % 32), (0, -w % 32))
    out = rec(np.pad(coded, pad, mode="edge"), np.pad(uncoded, pad, mode="edge"))
    return out[..., :h, :w]


def test_blend_weights_sum_to_one_across_a_shared_edge_and_vanish_at_it():
    tile, overlap = 128, 64
    a = R.blend_window(tile, overlap, first=True, last=False)
    b = R.blend_window(tile, overlap, first=False, last=True)
    shared = a[tile - overlap:] + b[:overlap]  # the next tile starts tile − overlap further on
    np.testing.assert_allclose(shared, 1.0, atol=1e-12)
    assert np.all(a[-overlap // 4:] == 0) and np.all(b[:overlap // 4] == 0)  # the outer quarter: weight 0
    assert np.all(a[:tile - overlap] == 1)
    assert R.tile_starts(160, 64, 32) == [0, 32, 64, 96] and R.tile_starts(128, 64, 32) == [0, 32, 64]
    assert R.tile_starts(192, 128, 32) == [0, 64]  # the last tile ends at the end
    assert R.tile_starts(96, 96, 192) == [0]  # one tile spans the axis, whatever the overlap


@pytest.mark.parametrize("shape", [(100, 150), (96, 128), (64, 200)])
def test_tiled_equals_whole_for_a_network_that_reads_2_px(shape):
    """Every pixel the blend reads lies ≥ overlap/4 = 8 px inside its tile, so a network that reads 2 px around
    a pixel gives the whole-image result exactly, at any image size (extended to multiples of 32)."""
    coded, uncoded = _views(*shape)
    rec = LocalNet()
    tiled = R.reconstruct_tiled(rec, coded, uncoded, tile=64, overlap=32)
    assert tiled.shape == (3, *shape) and tiled.dtype == np.float32
    np.testing.assert_allclose(tiled, _whole(rec, coded, uncoded), rtol=0, atol=2e-6)


def test_rows_come_out_in_order_each_once():
    coded, uncoded = _views(100, 70)
    rows = [(r, b.shape[1]) for r, b in R.iter_tiled(LocalNet(), coded, uncoded, tile=64, overlap=32)]
    assert [r for r, _ in rows] == sorted(r for r, _ in rows) and rows[0][0] == 0
    assert all(r + n == r2 for (r, n), (r2, _) in zip(rows, rows[1:])) and rows[-1][0] + rows[-1][1] == 100


@pytest.fixture(scope="module")
def captures():
    """96×128 captures of validation scenes through each shipped network's own PSF pair."""
    import functools

    from doefab.reconstruction import data

    @functools.lru_cache(maxsize=None)
    def make(task):
        rec = doefab.load_reconstructor(task)
        rng = np.random.default_rng(3)
        dm, resp = None, None
        if task == "hyperspectral":
            scene, resp = data.spectral_sample(rng, 128, "val"), doefab.sensor_response(rec.pair.wavelengths)
        else:
            scene, dm = data.depth_sample(rng, 128, "val")
            dm = dm[:96]
        c, u = doefab.simulate_captures(scene[:, :96], rec.pair, depth_map=dm, response=resp, seed=0)
        return rec, np.asarray(c), np.asarray(u)

    return make


# the stated tolerance (docs/guide/after-the-fab.md): relative to the mean |result|, 96×128 px in tiles of 64 with
# 32 px of overlap — the smallest tiling the networks take, so nearly every pixel lies in a blend
@pytest.mark.parametrize("task, mean_tol, max_tol", [("depth", 1e-2, 5e-2), ("hyperspectral", 1e-3, 2e-2)])
def test_tiled_matches_the_whole_image_with_the_shipped_network(captures, task, mean_tol, max_tol):
    rec, coded, uncoded = captures(task)
    whole = rec(coded, uncoded)
    tiled = R.reconstruct_tiled(rec, coded, uncoded, tile=64, overlap=32)
    assert tiled.shape == whole.shape
    scale = float(np.abs(whole).mean())
    diff = np.abs(tiled - whole)
    assert diff.mean() / scale < mean_tol and diff.max() / scale < max_tol, (diff.mean() / scale, diff.max() / scale)


def test_the_spectral_networks_light_is_estimated_once_for_all_tiles(captures, monkeypatch):
    """Each 64² tile would estimate its own light; the whole image's estimate (its central 256²) is used for
    every tile, and the network is left as it was."""
    import doefab.reconstruction.illuminant as ill
    import doefab.reconstruction.spectralnet as sn

    rec, coded, uncoded = captures("hyperspectral")
    calls = []
    real = ill.mix_illuminants

    def spy(c, *a, **k):
        calls.append(tuple(c.shape))
        return real(c, *a, **k)

    for module in (ill, sn):  # the tiling's estimate and the network's own
        monkeypatch.setattr(module, "mix_illuminants", spy)
    R.reconstruct_tiled(rec, coded, uncoded, tile=64, overlap=32)
    assert calls == [(1, 3, 96, 128)] and rec.model.light is None


def test_tiling_refusals_name_the_value_and_a_fix():
    coded, uncoded = _views(96, 128)
    rec = LocalNet()
    for kw, needle in (({"tile": 80}, "tile 80 must be a multiple of 32"), ({"overlap": 48}, "--overlap 64"),
                       ({"tile": 64, "overlap": 64}, "more than half the tile (64 px): give a tile of at least 128"),
                       # both rules in one message, each fix passing both
                       ({"tile": 128, "overlap": 200}, "multiple of 32 pixels, and the next one, 224, is more than "
                        "half the tile (128 px): give a tile of at least 448 px (--tile 448 --overlap 224) or an "
                        "overlap of at most 64 px"),
                       ({"tile": 100, "overlap": 96}, "tile 100 must be a multiple of 32 pixels, at least 64 (the "
                        "networks' input sides are multiples of 32): e.g. tile 192 (--tile 192)")):
        with pytest.raises(DoefabError, match=re.escape(needle)):
            R.reconstruct_tiled(rec, coded, uncoded, **{"tile": 64, "overlap": 32, **kw})
    with pytest.raises(DoefabError, match="differ in size"):
        R.reconstruct_tiled(rec, coded, uncoded[:, :64], tile=64, overlap=32)
    with pytest.raises(DoefabError, match="captures are in \\[0, 1\\]"):
        R.reconstruct_tiled(rec, coded * 2, uncoded, tile=64, overlap=32)
    with pytest.raises(DoefabError, match="200×48 px: the networks need at least 64 px on each side"):
        R.check_tiling(64, 32, (48, 200))


def test_an_image_narrower_than_a_tile_is_one_tile_across():
    """96×200 px in tiles of at most 128: one tile of 96 rows down, two of 128 columns across (the second ending
    at the extended image's end), exactly the whole image's result for the 2-px network."""
    coded, uncoded = _views(96, 200)
    calls = []
    net = LocalNet()

    class Counting(LocalNet):
        def __call__(self, c, u, psf=None):
            calls.append(c.shape)
            return net(c, u)

    tiled = R.reconstruct_tiled(Counting(), coded, uncoded, tile=128, overlap=32)
    assert calls == [(3, 96, 128), (3, 96, 128)]
    np.testing.assert_allclose(tiled, _whole(net, coded, uncoded), rtol=0, atol=2e-6)


def test_read_capture_scales_by_the_files_full_scale_after_the_black_level(tmp_path):
    dn = np.random.default_rng(1).integers(0, 65536, (32, 40, 3)).astype(np.float64)
    write_frame(tmp_path / "c.tiff", dn)
    got = R.read_capture(tmp_path / "c.tiff", black_level=1000)
    want = np.clip((np.moveaxis(dn, -1, 0) - 1000) / (65535 - 1000), 0, 1)
    assert got.shape == (3, 32, 40) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
    # values above the white level say it is wrong (no pixel records beyond its clip): refused, not clipped
    with pytest.raises(DoefabError, match=r"c\.tiff: 9\d\.\d% of its values lie above --white-level 4095 DN"):
        R.read_capture(tmp_path / "c.tiff", white_level=4095)
    few = dn % 4096
    few[0, :3] = 60000  # a few hot values above a linearity limit: clipped to it, as asked
    write_frame(tmp_path / "few.tiff", few)
    assert float(R.read_capture(tmp_path / "few.tiff", white_level=4095).max()) == 1.0
    twelve = dn % 4096  # a 12-bit camera's values in a 16-bit file
    write_frame(tmp_path / "t.tiff", twelve)
    at_4095 = np.moveaxis(twelve, -1, 0) / 4095
    np.testing.assert_allclose(R.read_capture(tmp_path / "t.tiff", white_level=4095), at_4095, rtol=1e-6)
    write_frame(tmp_path / "m.tiff", dn[..., 0])
    with pytest.raises(DoefabError, match=r"m\.tiff is a monochrome frame .*colour"):
        R.read_capture(tmp_path / "m.tiff")
    with pytest.raises(DoefabError, match="below the white level"):
        R.read_capture(tmp_path / "c.tiff", black_level=70000)


def test_read_capture_asks_for_the_white_level_of_wide_integer_files(tmp_path):
    dn = np.random.default_rng(2).integers(0, 4096, (16, 20, 3))
    np.save(tmp_path / "c.npy", dn.astype(np.int32))  # a 12-bit camera's values saved as 32-bit integers
    with pytest.raises(DoefabError, match=r"c\.npy holds integers wider than 16 bits.*give --white-level"):
        R.read_capture(tmp_path / "c.npy")
    got = R.read_capture(tmp_path / "c.npy", white_level=4095)
    np.testing.assert_allclose(got, np.moveaxis(dn, -1, 0) / 4095, rtol=1e-6)


def test_read_capture_refuses_fewer_than_8_bits(tmp_path, monkeypatch):
    import doefab.lab.frames as frames

    write_frame(tmp_path / "c.tiff", np.full((8, 8, 3), 7.0))
    monkeypatch.setattr(frames, "full_scale", lambda *a, **k: 15.0)  # a 4-bit file
    with pytest.raises(DoefabError, match=r"c\.tiff holds 4-bit values .* at least 8 bits"):
        R.read_capture(tmp_path / "c.tiff")


def test_unmix_undoes_the_per_column_mix_and_keeps_saturation():
    from doefab.imaging.crosstalk import DualPixelCrosstalk, mix_crosstalk

    w = 48
    a, b = np.linspace(0.02, 0.08, w), np.linspace(0.06, 0.03, w)
    coded, uncoded = (x * 0.8 for x in _views(16, w, seed=2))
    left, right = mix_crosstalk(uncoded, coded, a, b)  # the plain view is the left one (Eq. 29)
    # both photodiodes saturated in the last column, where α l→r = 0.08 > α r→l = 0.03: the exact unmix of (1, 1)
    # gives the coded view (1 − 2·0.08) / (1 − 0.11) = 0.94 there, yet it received at least full scale
    right[0, 0, -1] = left[0, 0, -1] = 1.0
    cam = DualPixelCrosstalk(a, b, estimate=(a, b))
    c, u = R.unmix_views(right.astype(np.float32), left.astype(np.float32), cam)
    mask = np.ones_like(c, bool)
    mask[0, 0, -1] = False
    np.testing.assert_allclose(c[mask], coded[mask], atol=2e-6)
    np.testing.assert_allclose(u[mask], uncoded[mask], atol=2e-6)
    assert c[0, 0, -1] == 1.0 and u[0, 0, -1] == 1.0
    with pytest.raises(DoefabError, match="holds 48 columns but the captures are 40 px wide"):
        R.unmix_views(c[..., :40].copy(), u[..., :40].copy(), cam)


def test_load_views_refuses_two_sizes_naming_both_files(tmp_path):
    write_frame(tmp_path / "c.tiff", np.zeros((64, 64, 3)))
    write_frame(tmp_path / "u.tiff", np.zeros((64, 96, 3)))
    with pytest.raises(DoefabError, match=r"c\.tiff is 64×64 px but .*u\.tiff is 96×64 px"):
        R.load_views(tmp_path / "c.tiff", tmp_path / "u.tiff")


def test_default_overlap_is_the_kernel_rounded_up_to_32():
    assert R.default_overlap(LocalNet()) == 32  # K = 31
    assert R.default_overlap(SimpleNamespace(pair=SimpleNamespace(coded=np.zeros((1, 1, 191, 191))))) == 192
    psf = SimpleNamespace(coded=np.zeros((1, 3, 95, 95)))  # a measured pair of a larger kernel than the network's
    assert R.default_overlap(LocalNet(), psf) == 96


def test_a_raw_capture_takes_each_channels_black_level_and_its_clipped_photosites(tmp_path):
    """A GRBG raw whose sites sit on 60, 70, 80 and 90 DN (R 70, G 60 and 90, B 80): each channel is scaled from
    its own black level; a single photosite at the white level marks its binned pixel clipped (1) in its channel,
    though binned it reads below full scale; a TIFF paired with it states another black level and is refused."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from test_lab_frames import _write_dng

    black = np.array([[60, 70], [80, 90]], np.float64)  # G R / B G
    m = np.tile(black, (16, 16)) + 1000.0
    m[5, 7] = 4095  # row 5, column 7: a green site (odd row, odd column) of binned pixel (2, 3)
    path = _write_dng(tmp_path / "c.dng", m, "GRBG", black=(60, 70, 80, 90), white=4095)
    got = R.read_capture(path)
    want = [1000 / (4095 - 70), 1000 / (4095 - 75), 1000 / (4095 - 80)]  # R, mean of the greens, B
    for k in range(3):
        expected = np.full((16, 16), want[k], np.float32)
        if k == 1:
            expected[2, 3] = 1.0
        np.testing.assert_allclose(got[k], expected, rtol=1e-6)
    assert R.read_capture(path, white_level=4095)[1, 2, 3] == 1.0  # a white level given: the same photosite test
    m[5, 7] = 3000  # below the raw's own white level, at a lower one given
    lower = _write_dng(tmp_path / "l.dng", m, "GRBG", black=(60, 70, 80, 90), white=4095)
    assert R.read_capture(lower)[1, 2, 3] < 1.0 and R.read_capture(lower, white_level=3000)[1, 2, 3] == 1.0
    black_rgb, white = R.capture_levels(path)
    assert black_rgb.tolist() == [70.0, 75.0, 80.0] and white == 4095.0
    write_frame(tmp_path / "u.tiff", np.full((16, 16, 3), 1000.0))
    with pytest.raises(DoefabError, match=r"state different black levels \(70/75/80 and 0/0/0 DN\)"):
        R.load_views(path, tmp_path / "u.tiff")


@pytest.mark.parametrize("top", [4095, 16000])
def test_a_12_or_14_bit_frame_in_a_16_bit_file_needs_its_white_level(tmp_path, top):
    """Unscaled, such a frame read 16× (4×) too dark and clipped nowhere; with --white-level it reads its scale."""
    frame = np.linspace(0, top, 64 * 64 * 3).reshape(64, 64, 3)
    write_frame(tmp_path / "c.tiff", frame)
    with pytest.raises(DoefabError, match=f"values stay within 14 bits \\(largest {top} DN.* give --white-level, the "
                                          f"camera's white level \\(4095 for 12-bit data, 16383 for 14-bit"):
        R.read_capture(tmp_path / "c.tiff")
    assert R.read_capture(tmp_path / "c.tiff", white_level=top).max() == pytest.approx(1.0)
    write_frame(tmp_path / "bright.tiff", frame * 65535 / top)  # a 16-bit frame that fills its range
    assert R.read_capture(tmp_path / "bright.tiff").max() == pytest.approx(1.0)


def test_a_frame_far_below_its_black_level_is_refused(tmp_path):
    """Values far below black (a wrong black level) were clipped to 0 silently; noise about black is kept."""
    frame = np.full((64, 64, 3), 0.4, np.float32)
    import tifffile

    frame[:8] = -0.5  # 12.5 % of the frame half the range below black (a float file: black 0, white 1)
    tifffile.imwrite(tmp_path / "far.tiff", frame, photometric="rgb")
    with pytest.raises(DoefabError, match=r"12\.5% of its values lie more than 5% of the range below the black"):
        R.read_capture(tmp_path / "far.tiff")
    frame[:8] = -0.01  # read noise about black
    tifffile.imwrite(tmp_path / "noise.tiff", frame, photometric="rgb")
    assert R.read_capture(tmp_path / "noise.tiff").min() == 0.0
