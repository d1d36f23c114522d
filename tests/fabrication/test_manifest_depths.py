"""A manifest's depth fields (``fabrication.manifest``): rounding passes, a wrong step or table entry fails."""

import json
from pathlib import Path

import doefab

REPO = Path(__file__).resolve().parents[2]


def test_rounding_passes_and_a_ten_percent_step_fails():
    from doefab.fabrication.manifest import depth_fields, depth_problems

    man = json.loads((REPO / "masks" / "half-ring" / "manifest.json").read_text())
    assert depth_problems(man) == []
    exact = depth_fields(doefab.FUSED_SILICA, man["design_wavelength_m"])
    rounded = dict(man, level_to_height_nm=[h + 0.0005 for h in exact["level_to_height_nm"]])
    assert depth_problems(rounded) == []  # float rounding of the written values passes
    step = dict(man, level_step_nm=man["level_step_nm"] * 1.1)
    assert [p.split(" =")[0] for p in depth_problems(step)] == ["level_step_nm"]
    table = dict(man, level_to_height_nm=[*man["level_to_height_nm"][:15], 1200.0])
    assert [p.split(" =")[0] for p in depth_problems(table)] == ["level_to_height_nm[15]"]
    edited = {**man["material"], "name": "N-BK7"}  # a built-in name with another material's coefficients
    assert "the record was edited" in " ".join(depth_problems(dict(man, material=edited)))


def test_a_material_of_the_users_own_is_checked_against_its_own_coefficients():
    from doefab.fabrication.manifest import depth_problems

    man = json.loads((REPO / "masks" / "half-ring" / "manifest.json").read_text())
    silica, bk7 = doefab.FUSED_SILICA, doefab.material_by_name("N-BK7")
    # the user's own name for the glass the depths were written for: consistent
    assert depth_problems(dict(man, material=doefab.Material("my silica", silica.b, silica.c_um).to_dict())) == []
    other = depth_problems(dict(man, material=doefab.Material("my glass", bk7.b, bk7.c_um).to_dict()))
    assert [p.split(" =")[0] for p in other][:2] == ["refractive_index_at_design_wavelength", "level_step_nm"]
