"""The holder's checks (``holder_cad.checks``) measure on the mesh; a failing holder leaves nothing printable;
nothing is written into a folder of the user's."""

import pytest

from doefab.errors import DoefabError


def test_holder_that_fails_a_check_leaves_nothing_printable(tmp_path, monkeypatch):
    import holder_cad.build as build
    from holder_cad.build import HolderCheckError, write_holder
    from holder_cad.params import HolderParams

    real = build.run_checks

    def failing_gap(parts, asm, p, expected_bodies):
        out = real(parts, asm, p, expected_bodies)
        if asm:
            out["passed"] = False
            out["fit_failures"] = ["die_to_pocket_gap_mm = 0.000 (needs ≥ 0.25)"]
            out["failing"] = out["fit_failures"]
        return out

    monkeypatch.setattr(build, "run_checks", failing_gap)
    with pytest.raises(HolderCheckError, match="die_to_pocket_gap_mm"):
        write_holder(HolderParams(), tmp_path, step=False, renders=False)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != ".doefab-output.json") == ["holder.FAILED.json"]


def test_holder_checks_measure_the_doe_distance_on_the_mesh():
    from holder_cad.build import assembly, build_parts
    from holder_cad.checks import run_checks
    from holder_cad.params import HolderParams

    p = HolderParams(washer_recess_mm=1.5, lens_face_to_glass_mm=4.0)
    parts = build_parts(p)
    c = run_checks(parts, assembly(parts, p), p, expected_bodies=2)
    # independent of the formula: the face sits washer_recess_mm above the lens-side end of the assembly
    assert c["doe_face_above_lens_side_end_mm"] == pytest.approx(1.5, abs=1e-3)
    assert c["doe_to_lens_mm"] == pytest.approx(4.0 - 2.5 + 1.5, abs=1e-3)
    assert {b["quantity"] for b in c["fit_bounds"]} >= {"doe_to_lens_mm", "thread_full_tooth_turns",
                                                        "die_to_pocket_clearance_mm", "wall_mm"}


def test_write_holder_never_writes_into_a_users_folder(tmp_path):
    from holder_cad.build import write_holder
    from holder_cad.params import HolderParams

    (tmp_path / "holder.stl").write_text("the user's own part")
    with pytest.raises(DoefabError, match="no doefab ownership marker"):
        write_holder(HolderParams(), tmp_path, step=False, renders=False)
    assert (tmp_path / "holder.stl").read_text() == "the user's own part"
    from doefab.io import mark_folder

    masks = tmp_path / "maskset"  # doefab's, but a mask set: no holder files go there
    masks.mkdir()
    mark_folder(masks, "masks")
    (masks / "manifest.json").write_text("{}")
    with pytest.raises(DoefabError, match="a doefab masks output"):
        write_holder(HolderParams(), masks, step=False, renders=False)
    assert sorted(p.name for p in masks.iterdir()) == [".doefab-output.json", "manifest.json"]
