"""Every committed mask set still verifies and matches the checksum of the design it came from."""

import json
from pathlib import Path

import pytest

import doefab
from doefab.fabrication.verify import verify_mask_set

MASKS = Path(__file__).resolve().parents[2] / "masks"
SETS = sorted(p for p in MASKS.glob("*") if (p / "manifest.json").is_file())


def test_three_default_sets_exist():
    assert {p.name for p in SETS} >= {"streak", "grating", "half-ring"}


@pytest.mark.parametrize("folder", SETS, ids=[p.name for p in SETS])
def test_committed_set_verifies(folder):
    design = doefab.Design.load(folder / "design")  # validates the level map against design.json
    man = json.loads((folder / "manifest.json").read_text())
    assert man["levels_sha256"] == json.loads((folder / "design" / "design.json").read_text())["levels_sha256"]
    rep = verify_mask_set(folder, design.levels, use_klayout=folder.name != "streak")
    assert rep["levels_reproduced"] and rep["marks_present"]
    assert all(v["mismatched_pixels_gdstk"] == 0 for v in rep["layers"].values())
    assert man["pitch_m"] == pytest.approx(design.camera.doe_pitch)


@pytest.mark.parametrize("folder", SETS, ids=[p.name for p in SETS])
def test_committed_sets_are_sixteen_levels_on_four_masks(folder):
    design = doefab.Design.load(folder / "design")
    man = json.loads((folder / "manifest.json").read_text())
    assert design.n_levels == man["n_levels"] == 16 and man["n_masks"] == 4
    assert sorted(L["layer"] for L in man["layers"] if L["purpose"] == "etch") == [1, 2, 3, 4]
    assert len(man["level_to_height_nm"]) == 16
