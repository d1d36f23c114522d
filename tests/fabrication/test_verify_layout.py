"""Verification accounts for every polygon of every layer: a copied mask set tampered with gdstk (the chrome
aperture or a key moved, a mark deleted, a rectangle added off the pixel grid or on a layer the set does not hold)
fails with the layer named, through gdstk, through KLayout and at the command line; an untouched copy verifies."""

import json
import re
import shutil

import gdstk
import numpy as np
import pytest

import doefab
from doefab.cli import main
from doefab.errors import CheckFailed
from doefab.fabrication.export import LevelMap, MaskOptions, export_masks
from doefab.fabrication.klayout_check import klayout_check
from doefab.fabrication.layout_check import expected_layout
from doefab.fabrication.marks import MarkSpec, key_site
from doefab.fabrication.verify import verify_mask_set


@pytest.fixture(scope="module")
def mask_set(tmp_path_factory):
    """A small 16-level set (100 × 100 pixels at 5.4 µm, 12 mm die), exported once."""
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100)
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    folder = tmp_path_factory.mktemp("set") / "m"
    export_masks(LevelMap(lv, cam), folder, MaskOptions(use_klayout=False), progress=False)
    return folder


def _copy(mask_set, tmp_path):
    dst = tmp_path / "copy"
    shutil.copytree(mask_set, dst)
    return dst


def _edit_gds(folder, edit):
    """Rewrite the set's GDS with gdstk after ``edit(cell)`` (coordinates in µm, the file's user unit)."""
    lib = gdstk.read_gds(str(folder / "doe.gds"))
    edit(lib.top_level()[0])
    lib.write_gds(str(folder / "doe.gds"))


def _move(layer, datatype, dx_um, near_um=None):
    """Move the polygons of ``layer/datatype`` (only those whose centre lies within 100 µm of ``near_um``)."""
    def edit(cell):
        for p in cell.polygons:
            (x0, y0), (x1, y1) = p.bounding_box()
            close = near_um is None or np.hypot((x0 + x1) / 2 - near_um[0], (y0 + y1) / 2 - near_um[1]) < 100
            if (p.layer, p.datatype) == (layer, datatype) and close:
                p.translate(dx_um, 0)
    return edit


def _delete_one(layer, datatype):
    def edit(cell):
        cell.remove(next(p for p in cell.polygons if (p.layer, p.datatype) == (layer, datatype)))
    return edit


def _add(layer, datatype, x0, y0, x1, y1):
    return lambda cell: cell.add(gdstk.rectangle((x0, y0), (x1, y1), layer=layer, datatype=datatype))


KEY0 = tuple(v / 1e3 for v in key_site(MarkSpec(12_000_000, 0, 5400), 0)[0])  # plate 0's first key site, µm
TAMPERS = {
    # (edit, what verification must name)
    "chrome aperture moved 200 µm": (_move(5, 0, 200.0), "layer 5/0 (chrome aperture"),
    "key moved 50 µm": (_move(10, 0, 50.0, KEY0), "layer 10/0 (alignment keys"),
    "key moved 1 µm": (_move(10, 0, 1.0, KEY0), "layer 10/0 (alignment keys"),
    "vernier bar deleted": (_delete_one(11, 2), "layer 11/2 (verniers and CD ladder, plate 2): "),
    "die outline deleted": (_delete_one(100, 0), "layer 100/0 (die outline): "),
    # a whole number of pixels right of the 100 × 100 grid (x ≤ 270 µm): on the pitch, off the grid
    "etch rectangle outside the grid": (_add(3, 0, 270 + 5.4 * 10, 0, 270 + 5.4 * 12, 10.8),
                                        "layer 3: 1 polygon(s) reach outside the 100 × 100 pixel grid"),
    "polygon on an unlisted layer": (_add(7, 0, 1000, 1000, 1100, 1100), "layer 7/0: 1 polygon(s)"),
    "polygon on the reserved label layer": (_add(63, 0, 1000, 1000, 1100, 1100), "layer 63/0: 1 polygon(s)"),
    "etch layer on another datatype": (_add(2, 1, -270, 259.2, -264.6, 270), "layer 2/1: 1 polygon(s)"),
}


def test_an_untouched_copy_rewritten_by_gdstk_still_verifies(mask_set, tmp_path, capsys):
    copy = _copy(mask_set, tmp_path)
    _edit_gds(copy, lambda cell: None)
    rep = verify_mask_set(copy)
    assert rep["levels_reproduced"] and rep["klayout"]["marks_match_manifest"]
    assert all(v["extra_um2"] == 0 and v["missing_um2"] == 0 for v in rep["marks"]["layers"].values())
    assert sorted(rep["marks"]["layers"]) == sorted(["5/0", "100/0"] + [f"{k}/{p}" for k in (10, 11) for p in range(5)])
    assert main(["masks", "--verify", str(copy), "--no-klayout"]) == 0
    assert "verified" in capsys.readouterr().out


def _refused(copy, needle, capsys) -> str:
    """verify_mask_set (gdstk) and ``doefab masks --verify --no-klayout`` (exit 3) both refuse ``copy``, naming
    ``needle``; the message."""
    with pytest.raises(CheckFailed) as exc:
        verify_mask_set(copy, use_klayout=False)
    assert needle in str(exc.value)
    assert main(["masks", "--verify", str(copy), "--no-klayout"]) == 3
    cap = capsys.readouterr()
    assert needle in cap.err and "verified" not in cap.out
    return str(exc.value)


@pytest.mark.parametrize("name", list(TAMPERS))
def test_tampered_layout_fails_naming_the_layer(mask_set, tmp_path, capsys, name):
    edit, needle = TAMPERS[name]
    copy = _copy(mask_set, tmp_path)
    _edit_gds(copy, edit)
    _refused(copy, needle, capsys)


@pytest.mark.parametrize("name", list(TAMPERS))
def test_klayout_refuses_the_same_tampering(mask_set, tmp_path, name):
    pytest.importorskip("klayout.db")
    edit, needle = TAMPERS[name]
    copy = _copy(mask_set, tmp_path)
    _edit_gds(copy, edit)
    man = json.loads((copy / "manifest.json").read_text())
    lv = np.load(copy / "design" / "levels.npy")[:, ::-1]  # as drawn: the pattern faces the lens
    layer = re.match(r"layer (\d+)", needle).group(1)
    with pytest.raises(CheckFailed, match=rf"KLayout: .*layer {layer}\b"):
        klayout_check(copy, man, lv, 16, expected_layout(man, 4))


def test_moves_report_where_and_how_much(mask_set, tmp_path):
    copy = _copy(mask_set, tmp_path)
    _edit_gds(copy, _move(10, 0, 50.0, KEY0))
    with pytest.raises(CheckFailed) as exc:
        verify_mask_set(copy, use_klayout=False)
    # a cross of two 160 × 10 µm bars moved 50 µm along x: the horizontal bar leaves 50 × 10 µm behind and
    # covers as much beyond its end, the vertical bar moves off entirely (1600 µm² each way, less their overlap)
    extra = 50 * 10 + 160 * 10 - 10 * 10
    msg = str(exc.value)
    assert f"{extra:.1f} µm² the manifest does not place there" in msg
    assert f"{extra:.1f} µm² missing that the manifest places" in msg
    assert "export the set again" in msg


def _edit_manifest(folder, edit):
    man = json.loads((folder / "manifest.json").read_text())
    edit(man)
    (folder / "manifest.json").write_text(json.dumps(man, indent=2))


def test_a_fresh_manifest_lists_each_layer_once(mask_set):
    man = json.loads((mask_set / "manifest.json").read_text())
    listed = [L["layer"] for L in man["layers"] + man["other_layers"]]
    assert sorted(listed) == [1, 2, 3, 4, 5, 10, 11, 63, 100]


@pytest.mark.parametrize("key, entry, needle", [
    ("other_layers", {"layer": 100, "datatype": 0, "purpose": "die outline"}, "other_layers[4] lists layer 100"),
    ("other_layers", {"layer": 5, "purpose": "chrome"}, "other_layers[4] lists layer 5"),
    ("layers", None, "layers[5] lists layer 4"),
])
def test_verify_refuses_a_layer_listed_twice(mask_set, tmp_path, capsys, key, entry, needle):
    copy = _copy(mask_set, tmp_path)
    _edit_manifest(copy, lambda man: man[key].append(entry or dict(man["layers"][-1])))
    with pytest.raises(CheckFailed, match=needle.replace("[", r"\[").replace("]", r"\]")):
        verify_mask_set(copy, use_klayout=False)
    assert main(["masks", "--verify", str(copy), "--no-klayout"]) == 3
    assert needle in capsys.readouterr().err


def test_verify_refuses_key_sites_the_layout_does_not_have(mask_set, tmp_path):
    copy = _copy(mask_set, tmp_path)

    def edit(man):
        man["key_sites_m"]["2"][0][0] += 50e-6

    _edit_manifest(copy, edit)
    with pytest.raises(CheckFailed, match=r"key_sites_m\['2'\]"):
        verify_mask_set(copy, use_klayout=False)


@pytest.mark.parametrize("shift_nm, ok", [(2, True), (3, False)])
def test_the_tolerance_is_two_database_units_in_both_readers(mask_set, tmp_path, shift_nm, ok):
    pytest.importorskip("klayout.db")
    copy = _copy(mask_set, tmp_path)
    _edit_gds(copy, _move(10, 0, shift_nm * 1e-3, KEY0))
    if ok:
        assert verify_mask_set(copy)["klayout"]["marks_match_manifest"]
        return
    with pytest.raises(CheckFailed, match="tolerance 2 nm.*layer 10/0 "):
        verify_mask_set(copy, use_klayout=False)
    man = json.loads((copy / "manifest.json").read_text())
    with pytest.raises(CheckFailed, match="KLayout: layer 10/0 .*tolerance 2 nm"):
        klayout_check(copy, man, np.load(copy / "design" / "levels.npy")[:, ::-1], 16, expected_layout(man, 4))


@pytest.fixture(scope="module")
def oasis_set(tmp_path_factory):
    """The small set of ``mask_set``, exported with an OASIS file beside its GDS file."""
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100)
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    folder = tmp_path_factory.mktemp("oas") / "m"
    export_masks(LevelMap(lv, cam), folder, MaskOptions(use_klayout=False, oasis=True), progress=False)
    return folder


def _edit_oas(folder, edit):
    """Rewrite the set's OASIS file with gdstk after ``edit(cell)`` (coordinates in µm); the GDS file stays."""
    lib = gdstk.read_oas(str(folder / "doe.oas"))
    edit(lib.top_level()[0])
    lib.write_oas(str(folder / "doe.oas"))


def _delete_layer(layer, datatype):
    def edit(cell):
        cell.filter([(layer, datatype)], remove=True)
    return edit


# the grid spans x, y in [-270, 270] µm: one pixel at its top-left corner
OAS_TAMPERS = {
    "rectangle added on etch layer 1": (_add(1, 0, -270, 264.6, -264.6, 270), "layer 1: "),
    "chrome aperture moved 200 µm": (_move(5, 0, 200.0), "layer 5/0 (chrome aperture"),
    "etch layer 2 missing": (_delete_layer(2, 0), "layer 2: "),
    "die outline missing": (_delete_layer(100, 0), "layer 100/0 (die outline): "),
}


def _reverse_order(cell):
    """The same geometry with its polygons stored in the reverse order."""
    polys = list(cell.polygons)
    cell.remove(*polys)
    cell.add(*polys[::-1])


@pytest.mark.parametrize("edit, identical", [(lambda cell: None, True), (_reverse_order, False)],
                         ids=["as written", "polygons in another order"])
def test_an_untouched_oasis_rewritten_by_gdstk_still_verifies(oasis_set, tmp_path, capsys, edit, identical):
    copy = _copy(oasis_set, tmp_path)
    _edit_oas(copy, edit)
    rep = verify_mask_set(copy, use_klayout=False)
    assert rep["oasis"]["file"] == "doe.oas"
    assert all(v["mismatched_pixels_gdstk"] == 0 for v in rep["oasis"]["layers"].values())
    assert sorted(rep["oasis"]["layers"]) == ["1", "2", "3", "4"]
    # a layer equal to the GDS file's, vertex for vertex, has passed there; another order is rasterised again
    assert all(("identical_to" in v) == identical for v in rep["oasis"]["layers"].values())
    assert rep["oasis"]["marks"] == rep["marks"]  # every mark layer, polygon count and area as in the GDS file
    assert main(["masks", "--verify", str(copy), "--no-klayout"]) == 0
    assert "verified doe.gds and doe.oas" in capsys.readouterr().out


@pytest.mark.parametrize("name", list(OAS_TAMPERS))
def test_tampered_oasis_fails_without_klayout_naming_file_and_layer(oasis_set, tmp_path, capsys, name):
    edit, needle = OAS_TAMPERS[name]
    copy = _copy(oasis_set, tmp_path)
    _edit_oas(copy, edit)
    msg = _refused(copy, f"{copy / 'doe.oas'}: ", capsys)
    assert msg.startswith(f"{copy / 'doe.oas'}: ") and needle in msg and "export the set again" in msg


@pytest.mark.parametrize("layer, what", [(100, "die outline"), (10, "alignment keys"), (11, "verniers")])
def test_verify_refuses_a_layout_layer_the_manifest_does_not_list(mask_set, tmp_path, capsys, layer, what):
    copy = _copy(mask_set, tmp_path)
    _edit_manifest(copy, lambda man: man.update(other_layers=[L for L in man["other_layers"] if L["layer"] != layer]))
    msg = _refused(copy, f"layer {layer}/0 ({what}", capsys)
    assert "manifest.json does not list" in msg
    # the fix the message names: add the entry it quotes back to other_layers
    entry = json.loads(re.search(r"add (\{.*?\}) to its other_layers", msg).group(1))
    assert entry["layer"] == layer
    _edit_manifest(copy, lambda man: man["other_layers"].append(entry))
    assert verify_mask_set(copy, use_klayout=False)["levels_reproduced"]


@pytest.mark.parametrize("value", [[100], "100", None, True, -1])
def test_verify_refuses_a_listed_layer_that_is_not_a_layer_number(mask_set, tmp_path, capsys, value):
    copy = _copy(mask_set, tmp_path)
    _edit_manifest(copy, lambda man: man["other_layers"][-1].update(layer=value))
    _refused(copy, f"other_layers[3].layer = {value!r} is not a GDS layer number", capsys)
