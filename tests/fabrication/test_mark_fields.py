"""A mask set a fab can align and inspect: every mark stands in clear glass on the chrome plate (a chrome key on
chrome is invisible, an etch plate's cross on chrome never reaches the silica), checked with polygon booleans on the
drawn marks and on a committed set's GDS as a reader sees it; and the report counts the pixels that touch only at a
corner, against a count made here by a different route (scipy's labelling)."""

import gdstk
import numpy as np
import pytest

from pathlib import Path

from doefab.fabrication.marks import MarkSpec, chrome_polygons, mark_polygons
from doefab.fabrication.verify import width_space_report


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
