"""Any number of levels a fab can make (L = 2 … 32, log2 L masks): bit planes, the exported layers read back by an
independent rasteriser, the manifest's depths against λ / (n − 1) / L, verification, and the fab's checks."""

import json
import math
import re

import gdstk
import numpy as np
import pytest

import doefab
from doefab.cli import main
from doefab.design.design import Design
from doefab.errors import CheckFailed, DoefabError
from doefab.fabrication.bitplanes import bit_planes, levels_from_planes
from doefab.fabrication.export import LevelMap, MaskOptions, export_masks
from doefab.fabrication.process import check_levels, check_min_feature, mask_count
from doefab.fabrication.verify import verify_mask_set
from doefab.optics.materials import N_BK7

N = 100
PITCH = 5.4e-6


@pytest.fixture(scope="module")
def cam():
    return doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=PITCH, doe_pixels=N, sensor_pitch=5.4e-6,
                         sensor_distance=50e-3, focus_distance=5.0, material=N_BK7)


def design_folder(cam, n_levels: int, path, seed: int = 0):
    """A design folder of random levels 0..L−1 (every level present) on the camera's grid."""
    lv = np.random.default_rng(seed).integers(0, n_levels, (N, N)).astype(np.uint8)
    lv[0, :n_levels] = np.arange(n_levels)
    d = Design(task="grating", task_params={}, camera=cam, wavelengths=(550e-9,), depths=(5.0,),
               height=doefab.levels_to_height(lv, cam, n_levels), levels=lv, n_levels=n_levels,
               metrics={"name": "m", "continuous": 0.5, "quantized": 0.5})
    d.save(path)
    return d


def etched_by_gds(folder) -> dict:
    """{layer: (N, N) bool} read with gdstk and rasterised by point-in-polygon tests at the pixel centres, laid out
    as the design (independent of doefab's rasteriser; the manifest says where pixel (0, 0) is and the mirror)."""
    man = json.loads((folder / "manifest.json").read_text())
    cell = gdstk.read_gds(str(folder / man["files"]["gds"])).top_level()[0]  # user unit: µm
    x0, y0 = (v * 1e6 for v in man["origin_m"])
    p = man["pitch_m"] * 1e6
    jj, ii = np.meshgrid(np.arange(N), np.arange(N))
    centres = np.stack([x0 + (jj.ravel() + 0.5) * p, y0 - (ii.ravel() + 0.5) * p], axis=1)
    out = {}
    for L in man["layers"]:
        if L["purpose"] == "etch":
            polys = cell.get_polygons(layer=L["layer"], datatype=0)
            got = np.array(gdstk.inside(centres, polys)).reshape(N, N) if polys else np.zeros((N, N), bool)
            out[L["layer"]] = got[:, ::-1] if man["mirrored_x"] else got
    return out


@pytest.mark.parametrize("n_levels", [2, 4, 8, 16, 32])
def test_bit_planes_for_any_level_count(n_levels):
    lv = np.random.default_rng(n_levels).integers(0, n_levels, (37, 41)).astype(np.uint8)
    planes = bit_planes(lv, n_levels)
    assert planes.shape[0] == mask_count(n_levels) == round(math.log2(n_levels))
    etched = sum(planes[m].astype(int) * 2**m for m in range(planes.shape[0]))
    assert np.array_equal(etched, n_levels - 1 - lv.astype(int))  # mask m etches bit m of L − 1 − level
    assert np.array_equal(levels_from_planes(planes), lv)
    with pytest.raises(DoefabError, match=f"0..{n_levels - 1}"):
        bit_planes(np.full((4, 4), n_levels), n_levels)


@pytest.mark.parametrize("bad", [3, 12, 64, 1, 0, True, 16.0, "16"])
def test_level_counts_a_fab_cannot_make_are_refused(bad):
    with pytest.raises(DoefabError, match="2, 4, 8, 16 or 32"):
        check_levels(bad)


def test_eight_level_design_makes_three_layers_that_rebuild_the_map(cam, tmp_path):
    d = design_folder(cam, 8, tmp_path / "design")
    rep = export_masks(d, tmp_path / "m", MaskOptions(use_klayout=False), design_dir=tmp_path / "design")
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    etch = [L for L in man["layers"] if L["purpose"] == "etch"]
    assert man["n_levels"] == 8 and man["n_masks"] == 3 and [L["layer"] for L in etch] == [1, 2, 3]
    assert sorted(rep["layers"]) == ["1", "2", "3"] and man["process_order"] == [5, 3, 2, 1]
    # depths from the substrate alone: d = λ / (n(λ) − 1) / 8, mask m etches 2^m·d, level k stands k·d high
    d_nm = 550e-9 / (float(N_BK7.index(550e-9)) - 1) / 8 * 1e9
    assert [L["etch_depth_nm"] for L in etch] == pytest.approx([d_nm, 2 * d_nm, 4 * d_nm], abs=1e-3)
    assert man["level_to_height_nm"] == pytest.approx([k * d_nm for k in range(8)], abs=1e-3)
    assert man["material"]["name"] == "N-BK7"
    etched = etched_by_gds(tmp_path / "m")
    total = sum(etched[lay].astype(int) << bit for bit, lay in enumerate((1, 2, 3)))
    assert np.array_equal(7 - total, d.levels)  # Σ 2^m·mask_m read back reproduces the level map
    assert verify_mask_set(tmp_path / "m", use_klayout=False)["levels_reproduced"]
    readme = (tmp_path / "m" / "README.txt").read_text()
    assert "8 levels" in readme and "Level k = 7 − Σ" in readme
    chrome = next(line for line in readme.splitlines() if "chrome aperture" in line)
    assert chrome.endswith("the first plate, aligned to no other.") and "None" not in readme  # words, not Python
    assert "aligns to plate 0." in next(line for line in readme.splitlines() if line.startswith("  layer 1 "))
    assert (tmp_path / "m" / "preview_layer3.png").is_file() and not (tmp_path / "m" / "preview_layer4.png").exists()


def test_thirty_two_level_design_makes_five_layers_and_marks_for_six_plates(cam, tmp_path):
    d = design_folder(cam, 32, tmp_path / "design", seed=1)
    export_masks(d, tmp_path / "m", MaskOptions(use_klayout=False, align_chain="sequential"),
                 design_dir=tmp_path / "design")
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    etch = {L["bit"]: L for L in man["layers"] if L["purpose"] == "etch"}
    assert sorted(etch) == [0, 1, 2, 3, 4] and [etch[b]["layer"] for b in range(5)] == [1, 2, 3, 4, 6]
    d_nm = man["level_step_nm"]
    assert d_nm == pytest.approx(550e-9 / (float(N_BK7.index(550e-9)) - 1) / 32 * 1e9, abs=1e-4)
    assert [etch[b]["etch_depth_nm"] for b in range(5)] == pytest.approx([d_nm * 2**b for b in range(5)], abs=2e-3)
    assert man["process_order"] == [5, 6, 4, 3, 2, 1]
    assert man["alignment_chain"] == {"5": 0, "4": 5, "3": 4, "2": 3, "1": 2}
    lib = gdstk.read_gds(str(tmp_path / "m" / "doe.gds"))
    assert {dt for lay, dt in lib.layers_and_datatypes() if lay == 10} == set(range(6))  # keys on every plate
    etched = etched_by_gds(tmp_path / "m")
    total = sum(etched[lay].astype(int) << bit for bit, lay in enumerate((1, 2, 3, 4, 6)))
    assert np.array_equal(31 - total, d.levels)
    rep = verify_mask_set(tmp_path / "m", use_klayout=False)
    assert rep["levels_reproduced"] and rep["marks_present"] and sorted(rep["layers"]) == ["1", "2", "3", "4", "6"]


def test_a_corrupted_depth_in_an_eight_level_manifest_fails_verification(cam, tmp_path, capsys):
    d = design_folder(cam, 8, tmp_path / "design")
    assert main(["masks", "--design", str(tmp_path / "design"), "--out", str(tmp_path / "m"), "--no-klayout"]) == 0
    assert main(["masks", "--verify", str(tmp_path / "m"), "--no-klayout"]) == 0
    path = tmp_path / "m" / "manifest.json"
    good = json.loads(path.read_text())
    bad = json.loads(path.read_text())
    layer = next(L for L in bad["layers"] if L.get("bit") == 2)
    layer["etch_depth_nm"] = round(layer["etch_depth_nm"] + 5.0, 3)
    path.write_text(json.dumps(bad))
    with pytest.raises(CheckFailed, match=r"etch_depth_nm = .* \(expected .* for bit 2\)"):
        verify_mask_set(tmp_path / "m", d.levels, use_klayout=False)
    capsys.readouterr()
    assert main(["masks", "--verify", str(tmp_path / "m"), "--no-klayout"]) == 3  # a product failing its checks
    assert "etch_depth_nm" in capsys.readouterr().err
    path.write_text(json.dumps(dict(good, n_levels=16)))  # a set that claims another level count
    with pytest.raises(CheckFailed, match="n_levels"):
        verify_mask_set(tmp_path / "m", d.levels, use_klayout=False)
    path.write_text(json.dumps(dict(good, n_masks=4)))  # 8 levels on 4 masks: the fields disagree
    with pytest.raises(CheckFailed, match=r"n_masks = 4 \(expected 3 for 8 levels\)"):
        verify_mask_set(tmp_path / "m", d.levels, use_klayout=False)


def test_the_export_follows_the_design_and_refuses_another_level_count(cam, tmp_path):
    d = design_folder(cam, 4, tmp_path / "design")
    with pytest.raises(DoefabError, match="has 4 levels"):
        export_masks(LevelMap(d.levels, cam, n_levels=16), tmp_path / "m", MaskOptions(use_klayout=False),
                     design_dir=tmp_path / "design")
    with pytest.raises(DoefabError, match="etch layer"):
        export_masks(d, tmp_path / "m", MaskOptions(use_klayout=False, etch_order=(4, 3, 2, 1)),
                     design_dir=tmp_path / "design")
    with pytest.raises(DoefabError, match="0..1"):  # levels 0..3 do not fit two levels
        export_masks(LevelMap(d.levels, cam, n_levels=2), tmp_path / "m", MaskOptions(use_klayout=False))
    assert not (tmp_path / "m").exists()


def test_marks_of_more_plates_need_a_larger_die(tmp_path):
    """Plate p's key sites sit 0.3 mm further in than plate p − 1's and its vernier sites one site further along
    the edges: around a 2.16 mm aperture, the smallest die that holds the marks of the chrome plate and four etch
    plates (16 levels) does not hold those of five (32 levels); the die the refusal names does."""
    from doefab.fabrication.marks import smallest_die_m

    small = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=10.8e-6, doe_pixels=200, sensor_pitch=5.4e-6,
                          sensor_distance=50e-3, focus_distance=5.0)
    lv = np.full((200, 200), 15, np.uint8)
    die = smallest_die_m(2.16e-3, 2.16e-3, 10.8e-6, 4, floor_m=0.0)
    export_masks(LevelMap(lv, small, n_levels=16), tmp_path / "a", MaskOptions(use_klayout=False, die_m=die))
    with pytest.raises(DoefabError, match=rf"6 plates do not fit a {die * 1e3:g} mm die") as exc:
        export_masks(LevelMap(lv, small, n_levels=32), tmp_path / "b", MaskOptions(use_klayout=False, die_m=die))
    assert not (tmp_path / "b").exists()
    need_mm = float(re.search(r"enlarge die_m to at least ([0-9.]+) mm", str(exc.value)).group(1))
    assert die * 1e3 < need_mm <= smallest_die_m(2.16e-3, 2.16e-3, 10.8e-6, 5, floor_m=0.0) * 1e3
    rep = export_masks(LevelMap(lv, small, n_levels=32), tmp_path / "b",
                       MaskOptions(use_klayout=False, die_m=need_mm * 1e-3))
    assert rep["marks_present"]


def test_min_feature_against_the_doe_pitch():
    assert check_min_feature(5.4e-6, 5.4e-6) == pytest.approx(1.0)  # equal is makeable
    assert check_min_feature(4e-6, 2e-6) == pytest.approx(2.0)
    with pytest.raises(DoefabError, match=r"DOE pitch 4 µm is finer than the fab's minimum feature 5 µm"):
        check_min_feature(4e-6, 5e-6)
    with pytest.raises(DoefabError, match="metres"):
        check_min_feature(5.4e-6, 5.0)  # 5 m: someone meant µm
    with pytest.raises(DoefabError, match="positive"):
        check_min_feature(5.4e-6, -1e-6)


def test_pixels_etched_under_a_marks_clear_field_are_refused(tmp_path):
    """A 32-level set on a 12 mm die around an 8.64 mm grid: the fifth etch plate's keys sit 1.75 mm in from the
    die's edges, inside the grid's corners (1.68 mm in), in clear fields the chrome leaves bare. A level map etched
    everywhere would be etched onto them there: refused, naming the place. The same map unetched outside the clear
    aperture (the chrome masks those pixels anyway) exports and verifies."""
    cam = doefab.Camera.preset("depth")
    n = cam.doe_pixels
    lv = np.zeros((n, n), np.uint8)  # level 0: every mask etches every pixel
    with pytest.raises(DoefabError, match=r"etches pixels in bare glass outside the clear aperture, round an "
                                          r"alignment mark or the split-line slits, around \(-?4.25, -?4.25\) mm"):
        export_masks(LevelMap(lv, cam, n_levels=32), tmp_path / "a", MaskOptions(use_klayout=False))
    assert not (tmp_path / "a").exists()
    y, x = (np.mgrid[:n, :n] + 0.5 - n / 2) * cam.doe_pitch
    lv[np.hypot(x, y) > cam.aperture_diameter / 2] = 31
    rep = export_masks(LevelMap(lv, cam, n_levels=32), tmp_path / "b", MaskOptions(use_klayout=False))
    assert rep["levels_reproduced"]


def test_marks_of_different_plates_never_overlap(tmp_path):
    """40 µm DOE pixels (a 40 µm CD: ladders 75 CD + 160 µm long) around a 2 mm aperture: on a 16.8 mm die the fifth
    plate's ladder would run over the chrome plate's key in the far corner; the export refuses it, naming a die on
    which, read back from the GDS, no plate's marks overlap another's (windows over the keys they show aside)."""
    cam = doefab.Camera(aperture_diameter=2e-3, doe_pitch=40e-6, doe_pixels=50)
    lv = np.full((50, 50), 15, np.uint8)
    with pytest.raises(DoefabError, match=r"[1-9]\d* overlapping\): enlarge die_m to at least ([0-9.]+) mm") as exc:
        export_masks(LevelMap(lv, cam), tmp_path / "a", MaskOptions(use_klayout=False, die_m=16.8e-3))
    die = float(re.search(r"at least ([0-9.]+) mm", str(exc.value))[1])
    export_masks(LevelMap(lv, cam), tmp_path / "b", MaskOptions(use_klayout=False, die_m=die * 1e-3))
    cell = gdstk.read_gds(str(tmp_path / "b" / "doe.gds")).top_level()[0]

    def marks(plate):  # µm; a window is a 260 µm square on layer 10
        polys = cell.get_polygons(layer=10, datatype=plate) + cell.get_polygons(layer=11, datatype=plate)
        return [p for p in polys if not (p.layer == 10 and abs(p.area() - 260.0**2) < 1e-3)]
    for a in range(5):
        for b in range(a + 1, 5):
            assert sum(p.area() for p in gdstk.boolean(marks(a), marks(b), "and")) == 0, (a, b)


def test_pixels_etched_beside_the_split_line_slits_are_refused(tmp_path):
    """A 2.16 mm aperture on a 2.7 mm grid: the chrome's slits on the y axis start 0.1 mm beyond the aperture, inside
    the grid. A column of etched pixels on the split line running the grid's full height would be etched there in
    bare glass (round the slit's centre, 1.08 + 0.1 + 0.6 / 2 = 1.48 mm out): refused; the same column cut at the
    clear aperture exports."""
    cam = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=10.8e-6, doe_pixels=250)
    lv = np.full((250, 250), 15, np.uint8)
    lv[:, 124:126] = 0
    with pytest.raises(DoefabError, match=r"in bare glass .* around \(0.00, -?1\.48\) mm"):
        export_masks(LevelMap(lv, cam), tmp_path / "a", MaskOptions(use_klayout=False))
    y = (np.arange(250) + 0.5 - 125) * 10.8e-6
    lv[np.abs(y) > 1.08e-3 - 10.8e-6, 124:126] = 15
    assert export_masks(LevelMap(lv, cam), tmp_path / "b", MaskOptions(use_klayout=False))["levels_reproduced"]
