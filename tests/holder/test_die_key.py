"""The die the fab dices is the die the holder's pocket takes, one way only: the mask set's dicing outline (layer
100, read back from the written GDS) is the pocket's die outline, its key sits on the coded half as the layout
places it (both pattern sides), and of the eight ways a square die can be laid in (four turns, each flipped or
not) only one fits the pocket (polygon booleans on the outlines)."""

import json
from pathlib import Path

import gdstk
import numpy as np
import pytest

import doefab
from doefab.fabrication.export import LevelMap, MaskOptions, export_masks
from holder_cad.params import HolderError, HolderParams
from holder_cad.recipe import die_outline, offset_convex

REPO = Path(__file__).resolve().parents[2]


def _outline_mm(gds: Path) -> np.ndarray:
    (poly,) = gdstk.read_gds(str(gds)).top_level()[0].get_polygons(layer=100, datatype=0)
    return poly.points / 1000.0  # µm → mm


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return sum(p.area() for p in gdstk.boolean(gdstk.Polygon(a), gdstk.Polygon(b), "xor")) < 1e-9


def test_the_committed_mask_sets_dice_the_die_the_holder_takes():
    pocket_die = die_outline(HolderParams())  # seen from the lens side, the cartridge's top in print orientation
    for task, name in (("half-ring", "halfring"), ("grating", "grating")):
        man = json.loads((REPO / "masks" / task / "manifest.json").read_text())
        assert man["mirrored_x"] and man["die_chamfer_m"] == pytest.approx(2e-3)
        # the layout is drawn as seen from the patterned face, which faces the lens: the holder's view
        got = _outline_mm(REPO / "masks" / task / f"{name}.gds")
        assert _same(got, pocket_die)
    # the key is on the DOE's coded half: where the etch plates etch (the plain half is the unetched top level)
    cell = gdstk.read_gds(str(REPO / "masks" / "half-ring" / "halfring.gds")).top_level()[0]
    etched = [p for layer in (1, 2, 3, 4) for p in cell.get_polygons(layer=layer, datatype=0)]
    xs = np.concatenate([p.points[:, 0] for p in etched])
    assert len(etched) > 1000 and xs.min() >= 0.0  # µm: every etched pixel at x ≥ 0
    cut = got[(np.abs(got[:, 0]) < 6 - 1e-9) & (np.abs(got[:, 1]) > 6 - 1e-9)]  # chamfer ends on the ±y edges
    assert len(cut) == 2 and np.all(cut[:, 0] > 0)
    assert cut[cut[:, 1] > 0, 0].min() < cut[cut[:, 1] < 0, 0].min()  # the larger chamfer at +y


@pytest.mark.parametrize("faces, coded", [("lens", 1), ("scene", -1)])
def test_the_outline_keys_the_coded_half_whichever_way_the_pattern_faces(tmp_path, faces, coded):
    cam = doefab.Camera(aperture_diameter=0.5e-3, doe_pitch=5.4e-6, doe_pixels=100)
    lv = np.full((100, 100), 15, np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, pattern_faces=faces))
    got = _outline_mm(tmp_path / "m" / "doe.gds")
    chamfered = got[(np.abs(got[:, 0]) < 6 - 1e-9) & (np.abs(got[:, 1]) > 6 - 1e-9)]  # vertices on the ±y edges
    assert len(chamfered) == 2 and np.all(np.sign(chamfered[:, 0]) == coded)
    # seen from the lens the coded half is at x > 0 either way: the scene-facing die is seen from its back
    from_lens = got * [-1, 1] if faces == "scene" else got
    assert _same(from_lens, die_outline(HolderParams()))


def _fits_somewhere(die: np.ndarray, pocket: np.ndarray, reach: float) -> bool:
    """Whether ``die`` lies inside ``pocket`` at some shift within ±``reach`` (a 21 × 21 grid of shifts)."""
    for dx in np.linspace(-reach, reach, 21):
        for dy in np.linspace(-reach, reach, 21):
            moved = gdstk.Polygon(die + [dx, dy])
            if sum(p.area() for p in gdstk.boolean(moved, gdstk.Polygon(pocket), "not")) < 1e-9:
                return True
    return False


@pytest.mark.parametrize("kw", [{}, {"die_chamfer_mm": 2.0, "clearance_mm": 0.25},
                                {"die_width_mm": 14.0, "die_height_mm": 13.0, "clearance_mm": 0.4,
                                 "die_chamfer_mm": 3.2}])
def test_only_the_right_way_round_fits_the_pocket_however_it_slides(kw):
    p = HolderParams(**kw)
    die = die_outline(p)
    pocket = offset_convex(die, p.clearance_mm)
    ways = []
    for flip in (False, True):
        for turn in range(4):
            c, s = np.cos(turn * np.pi / 2), np.sin(turn * np.pi / 2)
            d = die * [-1, 1] if flip else die
            ways.append(_fits_somewhere(d @ np.array([[c, s], [-s, c]]), pocket, 2 * p.clearance_mm))
    assert ways == [True] + [False] * 7


def test_a_chamfer_too_small_to_refuse_a_flipped_die_is_refused():
    # ((1 + √2)·0.25 + 0.1)·√2 / (1/2) = 1.99 mm: a die turned or face down, slid along the diagonal, must not go in
    with pytest.raises(HolderError, match=r"die_chamfer_mm \(1.5\) is too small .* set die_chamfer_mm = 2 or more"):
        HolderParams(die_chamfer_mm=1.5, clearance_mm=0.25)
    bad = HolderParams(die_chamfer_mm=1.5, clearance_mm=0.15)  # less play: this chamfer keys the die
    die = die_outline(bad)
    pocket = offset_convex(die, 0.25)  # ... but the pocket the refused holder would print: a flipped die goes in
    assert _fits_somewhere(die[::-1] * [-1, 1] @ np.array([[0.0, -1.0], [1.0, 0.0]]), pocket, 0.5)


def test_the_masks_default_key_on_a_small_die_is_one_the_holder_takes(tmp_path):
    """A 7 mm die: the mask export's default key is the holder's 2 mm chamfer (it was a quarter of the die, 1.75 mm,
    which the holder refuses at its default clearance), and a chamfer no pocket can key (0.3 mm: at the tightest
    0.05 mm clearance one needs more than ((1 + √2)·0.05 + 0.1)·√2 / 0.5 = 0.62 mm) is refused by the export. A
    chamfer of half the die is refused by the holder with the least chamfer that keys it, or, where none below half
    the side does, with what else to change."""
    from doefab.errors import DoefabError

    cam = doefab.Camera(aperture_diameter=2.16e-3, doe_pitch=10.8e-6, doe_pixels=200)
    lv = np.full((200, 200), 15, np.uint8)
    export_masks(LevelMap(lv, cam), tmp_path / "m", MaskOptions(use_klayout=False, die_m=7e-3))
    man = json.loads((tmp_path / "m" / "manifest.json").read_text())
    assert man["die_chamfer_m"] == pytest.approx(2e-3)
    from doefab.diekey import die_outline as key_outline

    assert _same(_outline_mm(tmp_path / "m" / "doe.gds"), key_outline(7.0, 7.0, 2.0))
    least = ((1 + np.sqrt(2)) * 0.05 + 0.1) * np.sqrt(2) / 0.5
    with pytest.raises(DoefabError, match=rf"keys the die in no holder's pocket .* exceed {least:.2f} mm"):
        export_masks(LevelMap(lv, cam), tmp_path / "n", MaskOptions(use_klayout=False, die_m=7e-3, die_chamfer_m=3e-4))
    with pytest.raises(HolderError, match=r"less than half the die's shorter side \(7 mm\): set die_chamfer_mm = 2$"):
        HolderParams(die_width_mm=7.0, die_height_mm=7.0, clear_aperture_mm=2.16, die_chamfer_mm=3.5)
    with pytest.raises(HolderError, match=r"no chamfer below half the side keys it at clearance_mm 0.8"):
        HolderParams(die_width_mm=7.0, die_height_mm=7.0, clear_aperture_mm=2.16, die_chamfer_mm=3.5, clearance_mm=0.8)
