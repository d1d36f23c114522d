"""A mask set a fab can align and inspect: every mark stands in clear glass on the chrome plate (a chrome key on
chrome is invisible, an etch plate's cross on chrome never reaches the silica), checked with polygon booleans on the
drawn marks and on a committed set's GDS as a reader sees it; and the report counts the pixels that touch only at a
corner, against a count made here by a different route (scipy's labelling)."""

import gdstk
import numpy as np
import pytest

from pathlib import Path

from doefab.fabrication.marks import MarkSpec, chrome_polygons, mark_polygons
from doefab.fabrication.inspection import width_space_report


def _area(polys) -> float:
    return sum(p.area() for p in polys)


def _grown(poly, d):
    (x0, y0), (x1, y1) = poly.bounding_box()
    return gdstk.rectangle((x0 - d, y0 - d), (x1 + d, y1 + d))


@pytest.mark.parametrize("n_plates", [1, 4])
def test_every_mark_of_every_plate_stands_in_clear_glass(n_plates):
    spec = MarkSpec(12_000_000, 4_320_000, 5_400)
    margin = spec.clear_margin_nm
    assert margin >= 20_000
    marks = mark_polygons(spec, {k: 0 for k in range(1, n_plates + 1)})
    chrome = chrome_polygons(spec, marks=marks)
    assert {(m.layer, m.datatype) for m in marks} >= {(10, 0), (11, 0), (10, n_plates), (11, n_plates)}
    for m in marks:
        if m.layer == 100:
            continue
        # no chrome under the mark nor within most of its margin: the aligner sees the mark against clear glass
        near = gdstk.boolean(_grown(m, 0.9 * margin), chrome, "and")
        assert _area(near) == 0, (m.layer, m.datatype, m.bounding_box())
    # the baffle is intact elsewhere: the chrome covers the die but for the aperture, the slits and the fields
    die = 12_000_000 ** 2
    aperture = np.pi * 4_320_000 ** 2
    fields = gdstk.boolean([_grown(m, margin) for m in marks if m.layer != 100], [], "or")
    slits = 2 * 20_000 * 600_000
    assert _area(chrome) == pytest.approx(die - aperture - slits - _area(fields), rel=1e-4)
    # and no clear field comes near the aperture (light through it would bypass the DOE)
    for f in fields:
        r = np.hypot(*np.asarray(f.points, float).T).min()
        assert r > 4_320_000 + margin


def test_a_committed_sets_marks_lie_in_clear_glass():
    cell = gdstk.read_gds(str(Path(__file__).resolve().parents[2] / "masks" / "half-ring" / "halfring.gds"))
    top = cell.top_level()[0]
    chrome = top.get_polygons(layer=5, datatype=0)
    marks = [p for p in top.get_polygons() if p.layer in (10, 11)]
    assert len(marks) > 50 and {p.datatype for p in marks} == {0, 1, 2, 3, 4}
    assert _area(gdstk.boolean(marks, chrome, "and")) == 0


def _corner_contacts_by_labels(p: np.ndarray) -> int:
    """Blocks where the etched pixels are one region under 8-connectivity but two under 4-connectivity."""
    from scipy import ndimage

    n = 0
    for i in range(p.shape[0] - 1):
        for j in range(p.shape[1] - 1):
            b = p[i:i + 2, j:j + 2]
            four = ndimage.label(b)[1]
            eight = ndimage.label(b, structure=np.ones((3, 3)))[1]
            n += int(four == 2 and eight == 1)
    return n


def test_the_report_counts_pixels_touching_only_at_a_corner():
    rng = np.random.default_rng(3)
    plane = rng.random((40, 50)) < 0.5
    got = width_space_report(plane, 1, 2e-6, (-40e-6, 50e-6))
    assert got["corner_contacts"] == _corner_contacts_by_labels(plane) > 0
    one = np.zeros((4, 4), bool)
    one[1, 1] = one[2, 2] = True  # one diagonal pair: its shared corner at x = 2 px, y = −2 px from the origin
    r = width_space_report(one, 1, 1e-6, (0.0, 0.0))
    assert r["corner_contacts"] == 1 and r["corner_locations_um"] == [[2.0, -2.0]]
    assert width_space_report(np.ones((5, 5), bool), 1, 1e-6, (0.0, 0.0))["corner_contacts"] == 0


def _bar_centres(polys, axis: int) -> np.ndarray:
    return np.sort([np.mean(np.asarray(p.points)[:, axis]) for p in polys])


@pytest.mark.parametrize("chain", ["chrome", "sequential"])
@pytest.mark.parametrize("shift_nm", [(750, 0), (0, -1250), (500, 2000)])
def test_each_plates_verniers_read_its_overlay(tmp_path, chain, shift_nm):
    """Every etch plate of an exported set has an x vernier on the top edge and a y vernier on the left edge against
    a reference on the plate it aligns to, at a site of its own. Plate 2 written shifted by (dx, dy) — here its bars
    are moved by that much — is read back by finding, from the drawn bars alone, the bar k whose two scales line
    up: k × 0.25 µm is the shift, along each axis."""
    import json

    from doefab.fabrication.export import LevelMap, MaskOptions, export_masks

    cam = __import__("doefab").Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100)
    lv = np.random.default_rng(0).integers(0, 16, (100, 100)).astype(np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, align_chain=chain))
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    ver = man["verniers"]
    cell = gdstk.read_gds(str(tmp_path / "m" / "doe.gds")).top_level()[0]
    seen = set()
    for plate, site in ver["sites_m"].items():
        ref = site["reference_plate"]
        assert ref == man["alignment_chain"][plate] and (chain == "sequential" or ref == 0)
        for axis, (sx, sy) in (("x", site["x"]), ("y", site["y"])):
            near = lambda p: np.hypot(*(np.asarray(p.points).mean(axis=0) * 1e-6 - (sx, sy))) < 0.35e-3  # µm → m
            mine = [p for p in cell.get_polygons(layer=11, datatype=int(plate)) if near(p)]
            refs = [p for p in cell.get_polygons(layer=11, datatype=ref) if near(p)]
            assert len(mine) == len(refs) == ver["bars"], (plate, axis)
            seen.add((round(sx, 6), round(sy, 6)))
            if plate != "2":
                continue
            a = 0 if axis == "x" else 1
            moved = _bar_centres(mine, a) + shift_nm[a] / 1e3  # µm
            k = np.argmin(np.abs(moved - _bar_centres(refs, a))) - ver["bars"] // 2
            assert k * ver["reading_step_nm"] == shift_nm[a], (axis, k)
    assert len(seen) == 2 * len(ver["sites_m"])  # a site of its own for each plate and axis


@pytest.mark.parametrize("name", ["format2_positive", "format2_negative"])
def test_a_set_of_format_2_verifies_as_it_was_drawn(tmp_path, name):
    """Sets written before format 3 (by the code of git 4c75425, kept in tests/fabrication/data: a 16-level
    positive-resist set aligned to the chrome, an 8-level negative-resist set aligned in sequence) verify as they
    were drawn: two-rectangle key crosses, windows on every etch plate, one 11-bar vernier per plate at the top
    edge, the README's words. Drawn with today's marks instead, the same manifest does not match its GDS."""
    import json
    import shutil

    from doefab.errors import DoefabError
    from doefab.fabrication.verify import verify_mask_set

    src = Path(__file__).resolve().parent / "data" / name
    assert json.loads((src / "manifest.json").read_text())["format"] == "doefab mask set 2"
    assert verify_mask_set(src, use_klayout=False)["levels_reproduced"]
    today = tmp_path / name
    shutil.copytree(src, today)
    man = json.loads((today / "manifest.json").read_text())
    (today / "manifest.json").write_text(json.dumps(man | {"format": "doefab mask set 3"}))
    with pytest.raises(DoefabError):
        verify_mask_set(today, use_klayout=False)
