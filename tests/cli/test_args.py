"""Flag parsers (``cli._args``): a unit hint, when followed, is accepted."""

import pytest


def test_unit_hint_when_followed_is_accepted():
    from doefab.cli._args import wavelength_nm

    with pytest.raises(Exception, match="write 550"):
        wavelength_nm("5.5e-07")
    assert wavelength_nm("550") == 550.0


def test_a_folder_of_mask_sets_given_as_a_design_names_the_sets_it_holds(tmp_path):
    from doefab.cli._args import design_folder
    from doefab.errors import DoefabError

    for name in ("b_set", "a_set"):
        (tmp_path / name / "design").mkdir(parents=True)
        (tmp_path / name / "design" / "design.json").write_text("{}")
    (tmp_path / "c_design").mkdir()
    (tmp_path / "c_design" / "design.json").write_text("{}")
    (tmp_path / "notes").mkdir()
    with pytest.raises(DoefabError, match="neither a design folder nor a mask set") as exc:
        design_folder(tmp_path)
    assert str(exc.value).endswith("it holds a_set, b_set, c_design: give one of them")
    for i in range(6):
        (tmp_path / f"d{i}").mkdir()
        (tmp_path / f"d{i}" / "design.json").write_text("{}")
    with pytest.raises(DoefabError) as exc:
        design_folder(tmp_path)
    assert str(exc.value).endswith("it holds a_set, b_set, c_design, d0, d1, d2 …: give one of them")
    (tmp_path / "notes" / "x.txt").write_text("")
    with pytest.raises(DoefabError) as exc:
        design_folder(tmp_path / "notes")
    assert "design.json is missing" in str(exc.value) and "it holds" not in str(exc.value)
