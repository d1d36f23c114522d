import json
import re

import gdstk
import numpy as np
import pytest

import doefab
from doefab.errors import DoefabError
from doefab.fabrication.bitplanes import (bit_planes, levels_from_planes, plane_rectangles, rasterize_manhattan,
                                          rasterize_rectangles)
from doefab.fabrication.export import LevelMap, MaskOptions, export_masks
from doefab.fabrication.gdsii import gds_real8
from doefab.fabrication.verify import verify_mask_set


@pytest.fixture(scope="module")
def cam():
    return doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100)


def test_gds_real8_known_values():
    # GDSII reals from the format spec: 1.0 = 0x41 10 00..., 1e-3 and 1e-9 as every GDS UNITS record holds
    assert gds_real8(1.0) == bytes.fromhex("4110000000000000")
    assert gds_real8(1e-3) == bytes.fromhex("3e4189374bc6a7f0")
    assert gds_real8(1e-9) == bytes.fromhex("3944b82fa09b5a54")


def test_hand_made_4x4_polygons_exact(cam, tmp_path):
    lv = np.full((100, 100), 15, np.uint8)
    lv[:4, :4] = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11], [12, 13, 14, 15]])
    planes = bit_planes(lv)
    # bit 3 of (15 - level) is set for levels 0..7: the top two rows of the block
    assert plane_rectangles(planes[3]).tolist() == [[0, 0, 4, 2]]
    # bit 0 set for even levels: columns 0 and 2 of the 4x4 block, all four rows
    assert sorted(plane_rectangles(planes[0]).tolist()) == [[0, 0, 1, 4], [2, 0, 3, 4]]
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, pattern_faces="scene"))
    lib = gdstk.read_gds(str(tmp_path / "m" / "doe.gds"))
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    pitch, (x0, y0) = 5400, man["origin_m"]
    x0, y0 = round(x0 * 1e9), round(y0 * 1e9)
    polys = lib.top_level()[0].get_polygons(layer=4, datatype=0)
    assert len(polys) == 1
    pts = sorted(map(tuple, np.rint(polys[0].points * 1000).astype(int).tolist()))  # user unit µm -> nm
    assert pts == sorted([(x0, y0), (x0 + 4 * pitch, y0), (x0 + 4 * pitch, y0 - 2 * pitch), (x0, y0 - 2 * pitch)])
    assert lib.unit == pytest.approx(1e-6) and lib.precision == pytest.approx(1e-9)


@pytest.mark.parametrize("seed", [0, 1])
def test_random_round_trip_zero_mismatches(cam, tmp_path, seed):
    rng = np.random.default_rng(seed)
    lv = rng.integers(0, 16, (100, 100)).astype(np.uint8)
    rep = export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(oasis=True))
    for st in rep["layers"].values():
        assert st["mismatched_pixels_gdstk"] == 0 and st["max_vertices"] <= 4000
    assert rep["levels_reproduced"] and rep["marks_present"]
    assert rep["klayout"]["checked"] and all(v["oasis_identical"] for v in rep["klayout"]["layers"].values())
    assert verify_mask_set(tmp_path / "m")["levels_reproduced"]
    for name in ("manifest.json", "README.txt", "preview_composite.png", "preview_layer1.png", "doe.oas"):
        assert (tmp_path / "m" / name).stat().st_size > 0


def test_rectangles_and_manhattan_raster_agree():
    rng = np.random.default_rng(3)
    plane = rng.random((37, 53)) > 0.6
    rects = plane_rectangles(plane)
    assert np.array_equal(rasterize_rectangles(rects, plane.shape), plane.astype(int))
    # the same rectangles as polygons (x = column, y = row), in both orientations, through the rasteriser
    pts = np.concatenate([[[c0, r0], [c1, r0], [c1, r1], [c0, r1]][::(1 if i % 2 else -1)]
                          for i, (c0, r0, c1, r1) in enumerate(rects)])
    idx = np.repeat(np.arange(len(rects)), 4)
    assert np.array_equal(rasterize_manhattan(pts, idx, plane.shape), plane.astype(int))
    # a keyhole polygon (square with a hole joined by a cut) rasterises to a ring
    ring = np.array([[0, 0], [6, 0], [6, 6], [0, 6], [0, 3], [2, 3], [2, 4], [4, 4], [4, 2], [2, 2], [2, 3], [0, 3]])
    r = rasterize_manhattan(ring, np.zeros(len(ring), int), (6, 6))
    expect = np.ones((6, 6), int)
    expect[2:4, 2:4] = 0
    assert np.array_equal(r, expect)


def test_levels_sum_reproduces_map():
    lv = np.arange(16, dtype=np.uint8).reshape(4, 4)
    assert np.array_equal(levels_from_planes(bit_planes(lv)), lv)


def test_vertex_cap_on_checkerboard(cam, tmp_path):
    lv = np.where((np.indices((100, 100)).sum(0) % 2) == 0, 0, 15).astype(np.uint8)
    rep = export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(vertex_cap=8, use_klayout=False))
    assert all(st["max_vertices"] <= 8 for st in rep["layers"].values())
    lib = gdstk.read_gds(str(tmp_path / "m" / "doe.gds"))
    assert max(len(p.points) for p in lib.top_level()[0].polygons) <= 8  # the chrome circle was fractured too
    assert rep["width_space"]["1"]["isolated_single_pixels"] == 5000


def test_manifest_fields(cam, tmp_path):
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, align_chain="sequential"))
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    etch = [L for L in man["layers"] if L["purpose"] == "etch"]
    assert [L["layer"] for L in etch] == [1, 2, 3, 4] and [L["bit"] for L in etch] == [0, 1, 2, 3]
    d = doefab.level_step(cam) * 1e9
    assert [L["etch_depth_nm"] for L in etch] == pytest.approx([d, 2 * d, 4 * d, 8 * d], abs=1e-3)
    assert man["pitch_m"] == pytest.approx(5.4e-6) and man["shape"] == [100, 100] and man["row0"] == "top"
    assert man["origin_m"] == pytest.approx([-270e-6, 270e-6])
    assert man["process_order"] == [5, 4, 3, 2, 1]
    assert man["alignment_chain"] == {"4": 0, "3": 4, "2": 3, "1": 2}
    assert man["level_to_height_nm"][15] == pytest.approx(15 * d, abs=1e-3)
    assert all("mask_polarity" in L and "resist_tone" in L for L in man["layers"])


@pytest.mark.parametrize("bad, msg", [
    (np.full((100, 100), 16), "0..15"),
    (np.full((100, 100), -1), "0..15"),
    (np.full((100, 100), 2.5), "non-integer"),
    (np.full((100, 100), np.nan), "NaN"),
    (np.zeros((99, 100), np.uint8), "does not match the camera grid"),
])
def test_bad_levels(cam, tmp_path, bad, msg):
    with pytest.raises(DoefabError, match=msg):
        export_masks(LevelMap(bad, cam), tmp_path / "m")
    assert not (tmp_path / "m").exists()


def test_bad_pitch_existing_output_and_no_half_written_set(cam, tmp_path, monkeypatch):
    lv = np.zeros((100, 100), np.uint8)
    with pytest.raises(DoefabError, match="not an integer number of nanometres"):
        export_masks(LevelMap(lv, cam.replace(doe_pitch=5.4003e-6)), tmp_path / "m")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "x").write_text("keep")
    for force in (False, True):  # a folder that is not a mask set is never replaced, even with force
        with pytest.raises(DoefabError, match="not a doefab masks output"):
            export_masks(LevelMap(lv, cam), tmp_path / "other", force=force)
    assert (tmp_path / "other" / "x").read_text() == "keep"
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False))
    with pytest.raises(DoefabError, match="already holds a doefab masks output"):
        export_masks(LevelMap(lv, cam), tmp_path / "m")
    before = (tmp_path / "m" / "manifest.json").read_bytes()
    # a failure during verification leaves the old set untouched and no staging debris
    import doefab.fabrication.export as ex

    def boom(*a, **k):
        raise DoefabError("injected verification failure")

    monkeypatch.setattr(ex, "verify_mask_set", boom)
    with pytest.raises(DoefabError, match="injected"):
        export_masks(LevelMap(lv, cam), tmp_path / "m", force=True)
    assert (tmp_path / "m" / "manifest.json").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m", "other"]


def test_tampered_gds_fails_verification(cam, tmp_path):
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False))
    lib = gdstk.read_gds(str(tmp_path / "m" / "doe.gds"))
    cell = lib.top_level()[0]
    cell.add(gdstk.rectangle((0, 0), (5.4, 5.4), layer=2))  # one extra pixel on layer 2 (µm)
    lib.write_gds(str(tmp_path / "m" / "doe.gds"))
    with pytest.raises(DoefabError, match="layer 2"):
        verify_mask_set(tmp_path / "m", use_klayout=False)


def test_pattern_toward_the_lens_mirrors_the_layout(cam, tmp_path):
    lv = np.full((100, 100), 15, np.uint8)
    lv[10:20, 0:5] = 0  # a block at the design's far left (coded half, x < 0)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False))  # default: pattern faces the lens
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    assert man["mirrored_x"] and man["pattern_faces"] == "lens"
    polys = gdstk.read_gds(str(tmp_path / "m" / "doe.gds")).top_level()[0].get_polygons(layer=4, datatype=0)
    xs = np.concatenate([p.points[:, 0] for p in polys])
    assert xs.min() == pytest.approx(270 - 5 * 5.4) and xs.max() == pytest.approx(270)  # µm: at the layout's right
    assert verify_mask_set(tmp_path / "m", use_klayout=False)["levels_reproduced"]
    # the drawn grid's top-left corner (origin_m, µm here) is the layout's left edge, where design column N−1 lies
    assert man["origin_m"][0] * 1e6 == pytest.approx(-270)
    assert "level-map (design) pixel [0, N−1]" in man["origin_means"]
    export_masks(LevelMap(lv, cam), tmp_path / "s", MaskOptions(use_klayout=False, pattern_faces="scene"))
    scene_facing = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert "level-map (design) pixel [0, 0]" in scene_facing["origin_means"]
    # the marks' pitches follow the CD (manifest verniers): no layer purpose states a fixed one
    assert man["verniers"]["reference_pitch_nm"] and not any(re.search(r"\d\s*µm", o["purpose"])
                                                              for o in man["other_layers"])


def test_export_takes_a_design_not_its_parts(tmp_path):
    """A level map and its camera given apart are refused with the fix (a Design, or LevelMap)."""
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100, sensor_pitch=5.4e-6,
                        sensor_distance=50e-3, focus_distance=5.0)
    lv = np.zeros((100, 100), np.uint8)
    with pytest.raises(DoefabError, match=r"takes a design .*LevelMap\(levels, camera, n_levels\)"):
        export_masks(lv, tmp_path / "m")
    with pytest.raises(TypeError):  # the old call, parts apart
        export_masks(lv, cam, tmp_path / "m", MaskOptions(use_klayout=False), None)
    export_masks(LevelMap(lv, cam, n_levels=4), tmp_path / "ok", MaskOptions(use_klayout=False), progress=False)
    assert json.loads((tmp_path / "ok" / "manifest.json").read_text())["n_levels"] == 4
    assert not (tmp_path / "m").exists()


def test_a_negative_resist_set_keeps_its_keys_in_clear_glass(cam, tmp_path):
    """Positive resist: the etch plates are dark field, clear inside their polygons, so each draws a 260 µm window
    over the chrome keys it aligns to. Negative resist: the plates are clear field (chrome inside the polygons), so
    a drawn window would be chrome over those keys: none is drawn, and each plate's own cross is all it draws on
    layer 10. Both sets verify."""
    from doefab.fabrication.marks import KEY_ARM_NM, KEY_WIDTH_NM, WINDOW_NM

    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    cross = 2 * (2 * KEY_ARM_NM * KEY_WIDTH_NM) - KEY_WIDTH_NM**2  # nm²: two arms, their overlap once
    for resist, window_area in (("positive", 4 * WINDOW_NM**2), ("negative", 0)):
        out = tmp_path / resist
        export_masks(LevelMap(lv, cam), out, MaskOptions(use_klayout=False, resist=resist))
        cell = gdstk.read_gds(str(out / "doe.gds")).top_level()[0]
        for plate in (1, 2, 3, 4):
            polys = cell.get_polygons(layer=10, datatype=plate)
            drawn = gdstk.boolean(polys, [], "or")  # nm² of the plate's layer 10, overlaps counted once
            area = sum(p.area() for p in drawn) * 1e6  # µm² → nm²
            assert area == pytest.approx(window_area + 4 * cross, rel=1e-6), (resist, plate)
        assert verify_mask_set(out, use_klayout=False)["levels_reproduced"]
        readme = (out / "README.txt").read_text()
        assert ("clear window" in readme) == (resist == "positive")


def test_a_cd_wider_than_the_pixels_is_refused_where_the_map_has_narrower_features(cam, tmp_path):
    """A CD of two pixels: refused for a map with single-pixel features (the plates would carry what that CD cannot
    write), taken for a map whose features and spaces are all 2 × 2 pixel blocks — and then every plate, the chrome
    one too, states that CD, and every mark is at least that wide."""
    rng = np.random.default_rng(0)
    fine = rng.integers(0, 16, (100, 100)).astype(np.uint8)
    with pytest.raises(DoefabError, match=r"critical dimension 10.8 µm is wider than the 5.4 µm pixel pitch"):
        export_masks(LevelMap(fine, cam), tmp_path / "a", MaskOptions(use_klayout=False, cd_m=10.8e-6))
    assert not (tmp_path / "a").exists()
    blocks = np.kron(rng.integers(0, 16, (50, 50)), np.ones((2, 2))).astype(np.uint8)
    export_masks(LevelMap(blocks, cam), tmp_path / "b", MaskOptions(use_klayout=False, cd_m=10.8e-6))
    man = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert {L["critical_dimension_nm"] for L in man["layers"]} == {10_800}
    cell = gdstk.read_gds(str(tmp_path / "b" / "doe.gds")).top_level()[0]
    marks = [p for p in cell.polygons if p.layer in (10, 11)]
    narrowest = min(min(np.ptp(p.points[:, 0]), np.ptp(p.points[:, 1])) for p in marks)  # µm
    assert narrowest == pytest.approx(10.8)


def test_the_largest_die_exports_and_verifies(cam, tmp_path):
    """A 300 mm die, the top of the range, as `--die-mm 300` gives it (300 × 1e-3 m is 0.30000000000000004 in
    floating point): the manifest states 0.3 m and the set verifies."""
    lv = np.full((100, 100), 15, np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, die_m=300 * 1e-3))
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    assert man["die_m"] == 0.3 and man["key_sites_m"]["0"][0] == [-0.14975, -0.14975]
    assert verify_mask_set(tmp_path / "m", use_klayout=False)["levels_reproduced"]


def test_no_mark_is_exposed_twice_and_the_substrate_is_stated(cam, tmp_path):
    """Writers that do not merge shapes expose overlapping polygons twice: on every plate's mark layers (10, 11)
    the polygons' summed area equals their union's (the key crosses are one polygon each). The substrate's
    thickness, the holder's die thickness, is stated in the manifest and the fab README, and `plates` lists each
    plate's layers alike as layer/datatype."""
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, substrate_thickness_m=0.7e-3))
    cell = gdstk.read_gds(str(tmp_path / "m" / "doe.gds")).top_level()[0]
    for layer in (10, 11):
        for plate in range(5):
            polys = cell.get_polygons(layer=layer, datatype=plate)
            union = gdstk.boolean(polys, [], "or")
            summed, merged = sum(p.area() for p in polys), sum(p.area() for p in union)
            assert summed == pytest.approx(merged, rel=1e-9), (layer, plate)
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    assert man["substrate_thickness_m"] == 0.7e-3 and "0.7 mm thick" in (tmp_path / "m" / "README.txt").read_text()
    assert man["plates"]["0"] == ["5/0", "10/0", "11/0"] and man["plates"]["4"] == ["4/0", "10/4", "11/4"]
