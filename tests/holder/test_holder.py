import json
import re
import zipfile

import numpy as np
import pytest

from holder_cad.build import HolderCheckError, build_parts, write_holder
from holder_cad.checks import aperture_clear, pocket_gap
from holder_cad.params import HolderError, HolderParams
from holder_cad.recipe import thread_section


def test_default_part_passes_every_check(tmp_path):
    rep = write_holder(HolderParams(), tmp_path, step=False, renders=False)
    c = rep["checks"]
    assert c["passed"] and c["total_bodies"] == c["declared_bodies"] == 2
    for body in c["bodies"].values():
        assert body["status"] == "NoError" and body["watertight"] and body["is_volume"]
        assert body["min_wall_mm"] >= 1.2 - 0.01
        assert body["overhang_area_beyond_45deg_mm2"] == 0.0
    assert c["die_to_pocket_gap_mm"] == pytest.approx(0.25, abs=0.01)
    assert c["aperture_rays_blocked"] == 0
    assert rep["coupon_checks"]["passed"]
    # the DOE's face sits as deep as the screw heads need: an ISO 1207 M2 cheese head (1.3 mm) on an M2 washer
    # (0.3 mm) stays 0.2 mm in front of the glass, 3.5 − 2.5 mm beyond the thread's tip: the least tenth is 0.8 mm
    assert rep["doe_to_lens_mm"] == pytest.approx(3.5 - 2.5 + 0.8)
    assert rep["doe_to_lens_mm"] - 0.3 - 1.3 >= 0.2 - 1e-6  # measured on the mesh: heads clear of the glass
    saved = json.loads((tmp_path / "holder.json").read_text())
    assert saved["parameters"]["thread_diameter_mm"] == 49.0 and saved["units"] == "mm"
    for f in ("holder.stl", "holder.3mf", "coupon.stl"):
        assert (tmp_path / f).stat().st_size > 10_000
    # the 3MF holds one named object per body, in millimetres: a slicer lists and places them one by one
    model = zipfile.ZipFile(tmp_path / "holder.3mf").read("3D/3dmodel.model").decode()
    assert re.search(r'<model[^>]*\bunit="millimeter"', model)
    assert re.findall(r'<object[^>]*\bname="([^"]+)"', model) == ["base", "cartridge"]
    assert len(re.findall(r"<item\b", model)) == 2


@pytest.mark.parametrize("kw, need", [({}, 0.8), ({"screw_head_mm": 2.0}, 1.5),
                                      ({"lens_face_to_glass_mm": 4.0, "washer_thickness_mm": 0.5}, 0.5)])
def test_screw_heads_clear_the_lens_glass(kw, need):
    """The heads on their washers sweep the front glass as the base turns: a recess that leaves them less than
    0.2 mm in front of the glass's vertex plane is refused with the least that works (glass 3.5 mm behind the
    filter face (4.0 mm), the thread's tip 2.5 mm in front of it)."""
    glass = kw.get("lens_face_to_glass_mm", 3.5) - 2.5
    head = kw.get("washer_thickness_mm", 0.3) + kw.get("screw_head_mm", 1.3)
    assert HolderParams(**kw).washer_recess_mm == pytest.approx(max(need, kw.get("washer_thickness_mm", 0.3)))
    assert glass + need - head >= 0.2 - 1e-9 and glass + need - 0.1 - head < 0.2  # the least tenth that clears
    with pytest.raises(HolderError, match=f"screw_head_to_glass_mm.*set washer_recess_mm = {need:g} or more"):
        HolderParams(**kw, washer_recess_mm=round(need - 0.1, 1))
    HolderParams(**kw, washer_recess_mm=need)


def test_the_lens_side_end_stays_clear_of_the_glass():
    """The thread's tip, with the cartridge's end flush with it, turns 0.2 mm or more in front of the glass: a
    thread as long as the lens's glass is deep is refused, however deep the washers could sink; a slip-fit plate
    rests on the barrel's face, 3.5 mm in front of the glass, and sinks the washers just below its end."""
    with pytest.raises(HolderError, match=r"lens_side_end_to_glass_mm .* set thread_length_mm between 2.1 and 3.3"):
        HolderParams(thread_length_mm=3.4)
    for t in (2.1, 3.3):  # both ends of the range named: two full turns of the 0.75 mm pitch, 0.2 mm from the glass
        HolderParams(thread_length_mm=t)
    # a glass too near the filter face for two full turns: no thread length works, and the message says so
    for kw in ({"lens_face_to_glass_mm": 2.0}, {"thread_diameter_mm": 95.0, "lens_face_to_glass_mm": 2.9}):
        with pytest.raises(HolderError, match=r"lens_side_end_to_glass_mm .* leaves room for .*\(mount = \"slip\"\)"):
            HolderParams(**kw)
    HolderParams(thread_diameter_mm=95.0, lens_face_to_glass_mm=3.0)  # its 2.8 mm thread, 0.2 mm from the glass
    slip = HolderParams(mount="slip")
    assert slip.washer_recess_mm == pytest.approx(0.3) and slip.doe_to_lens_mm == pytest.approx(3.5 + 0.3)


@pytest.mark.parametrize("recess", [None, 1.5])
def test_retention_holes_grip_below_the_washers_seat(recess):
    """The retention screws' pilot holes reach 3.4 mm below the washers' seat (the DOE's face) however deep the
    recess: read on the cartridge mesh, whose sections lose both holes' area (2 × π × 0.85²) at that depth."""
    p = HolderParams(**({} if recess is None else {"washer_recess_mm": recess}))
    cart = build_parts(p)["cartridge"]
    bottom = cart.bounding_box()[5] - p.washer_recess_mm - 3.4
    step = cart.slice(bottom - 0.01).area() - cart.slice(bottom + 0.01).area()
    assert step == pytest.approx(2 * np.pi * 0.85 ** 2, rel=0.1)
    # a cartridge too short for holes that deep below a deep recess is refused before anything is built
    with pytest.raises(HolderError, match=r"retention_hole_floor_mm .* a smaller washer_recess_mm"):
        HolderParams(mount="slip", flange_height_mm=2.0, washer_recess_mm=1.5)


def test_washer_recesses_stay_off_the_keyed_chamfer(tmp_path):
    """A 10 mm die keyed by a 2 mm chamfer: its pocket's straight side ends 5 − 2 + 0.25·(√2 − 1) = 3.10 mm from
    the die's middle, and 6 mm washers' recesses (3.25 mm either side) would cut into the key, leaving a knife-edge
    the wall check measured at 0.05 mm. Refused with washers that end on the straight side, which build."""
    kw = {"thread_diameter_mm": 30.5, "die_width_mm": 10.0, "die_height_mm": 10.0, "clear_aperture_mm": 6.0}
    with pytest.raises(HolderError, match=r"keyed chamfer .* set washer_diameter_mm = 5.7 or less, or "
                                          r"die_height_mm = 11 or more"):
        HolderParams(**kw)
    # a 9.6 mm die: no washer both overlaps it by 0.5 mm and ends before the chamfer, so only a taller die is named
    with pytest.raises(HolderError, match=r"knife-edge of plastic: set die_height_mm = 11 or more$"):
        HolderParams(**{**kw, "die_width_mm": 9.6, "die_height_mm": 9.6, "clear_aperture_mm": 5.0})
    rep = write_holder(HolderParams(**kw, washer_diameter_mm=5.7), tmp_path, step=False, renders=False)
    assert rep["checks"]["passed"] and rep["checks"]["bodies"]["cartridge"]["min_wall_mm"] >= 1.2 - 0.01


@pytest.mark.parametrize("kw", [
    {"thread_diameter_mm": 52.0, "flange_diameter_mm": 60.0},
    {"thread_diameter_mm": 58.0, "flange_diameter_mm": 66.0},
    {"die_width_mm": 13.0, "die_height_mm": 12.0, "die_thickness_mm": 1.5, "clearance_mm": 0.3, "die_chamfer_mm": 2.4},
    {"mount": "slip", "flange_diameter_mm": 70.0},
])
def test_parameter_sweep_passes(tmp_path, kw):
    rep = write_holder(HolderParams(**kw), tmp_path, step=False, renders=False)
    assert rep["checks"]["passed"], rep["checks"]


def test_thread_geometry_is_the_filter_thread():
    p = HolderParams()
    parts = build_parts(p)
    base = parts["base"]
    # crest radius, root radius and pitch read back from the mesh, against the parameters (M49 x 0.75)
    sec = np.array(base.slice(1.0).to_polygons()[0])
    polys = base.slice(1.0).to_polygons()
    r_all = np.concatenate([np.hypot(*np.array(q).T) for q in polys])
    play = 0.2165 * 0.75 + 0.075  # the least for the 45° tooth in the 60° groove, and 0.15 mm axially at the flanks
    assert r_all.max() == pytest.approx(49.0 / 2 - play, abs=0.01)
    sec = thread_section(p)
    assert np.hypot(*sec.T).min() == pytest.approx(49.0 / 2 - play - 0.3, abs=1e-3)
    # one pitch up, the section repeats (single-start thread, pitch 0.75 mm)
    a = sorted(np.round(np.hypot(*np.array(max(base.slice(0.9).to_polygons(), key=len)).T), 3))
    b = sorted(np.round(np.hypot(*np.array(max(base.slice(0.9 + 0.75).to_polygons(), key=len)).T), 3))
    assert np.allclose(a[-50:], b[-50:], atol=2e-3)


def test_checks_detect_defects():
    p = HolderParams()
    parts = build_parts(p)
    # a too-small pocket: gap measured against a die larger than the pocket allows is zero
    assert pocket_gap(parts["cartridge"], p.replace(die_width_mm=12.6), 10.9 - 0.6 - 0.5) == 0.0
    # a plate across the aperture blocks the axial rays
    from manifold3d import Manifold

    plate = Manifold.cube((4.0, 4.0, 1.0)).translate((-2.0, -2.0, -5.0))
    assert aperture_clear([plate], p.clear_aperture_mm / 2) > 0


@pytest.mark.parametrize("kw, names", [
    ({"clear_aperture_mm": 11.0}, "clear_aperture_mm"),
    ({"wall_mm": 0.3}, "wall_mm"),
    ({"clearance_mm": 0.0}, "clearance_mm"),
    ({"clearance_mm": -0.1}, "clearance_mm"),
    ({"flange_diameter_mm": 52.0}, "flange_diameter_mm"),
    ({"mount": "glue"}, "mount"),
    ({"die_width_mm": 40.0, "die_height_mm": 40.0}, "die"),
    ({"thread_depth_mm": 0.5}, "thread_depth_mm"),
])
def test_invalid_parameters_refused(kw, names):
    with pytest.raises(HolderError, match=names):
        HolderParams(**kw)


def test_stl_and_step_load_back_with_same_volume(tmp_path):
    cq = pytest.importorskip("cadquery")
    import trimesh

    p = HolderParams()
    rep = write_holder(p, tmp_path, step=True, renders=True)
    assert rep["checks"]["brep_agrees"]
    mesh_volume = sum(b["volume_mm3"] for b in rep["checks"]["bodies"].values())
    stl = trimesh.load(tmp_path / "holder.stl")
    assert stl.volume == pytest.approx(mesh_volume, rel=1e-4)
    step = cq.importers.importStep(str(tmp_path / "holder.step"))
    assert step.val().Volume() == pytest.approx(mesh_volume, rel=0.01)
    for name, v in rep["brep_vs_mesh"].items():
        assert v["volume_rel_diff"] <= 0.01 and v["bbox_max_diff_mm"] <= 0.05
    for f in ("render_front.png", "render_side.png", "render_iso.png"):
        assert (tmp_path / f).stat().st_size > 5000


def test_cli_bad_parameter(tmp_path, capsys):
    from doefab.cli import main

    assert main(["holder", "--out", str(tmp_path), "--set", "wall_mm=0.2", "--no-step", "--no-renders"]) == 2
    assert "wall_mm" in capsys.readouterr().err
    assert main(["holder", "--out", str(tmp_path), "--set", "colour=red"]) == 2


def test_facet_sag_is_read_from_the_mesh():
    from manifold3d import Manifold

    from holder_cad.checks import facet_sag_mm

    for r, n in ((28.5, 128), (78.0, 128), (78.0, 32)):
        m = Manifold.cylinder(2.0, r, circular_segments=n)
        mesh = m.to_mesh()
        v = np.asarray(mesh.vert_properties)
        v = v[(v[:, 2] == 0.0) & (np.hypot(v[:, 0], v[:, 1]) > r / 2), :2]  # the bottom rim's vertices
        ring = v[np.argsort(np.arctan2(v[:, 1], v[:, 0]))]  # in angle order
        mids = 0.5 * (ring + np.roll(ring, -1, axis=0))  # facet midpoints, nearest the axis
        assert facet_sag_mm(m, n) == pytest.approx(r - np.hypot(*mids.T).min(), rel=1e-3)  # float32 vertices


def test_overhangs_narrower_than_the_facets_are_not_counted():
    from manifold3d import Manifold

    from holder_cad.checks import facet_sag_mm, overhang_area

    def stack(r_bottom):  # a 78 mm radius disc resting on a narrower one: a downward ledge of r − r_bottom
        return Manifold.cylinder(2.0, r_bottom, circular_segments=128) + Manifold.cylinder(
            2.0, 78.0, circular_segments=128).translate((0.0, 0.0, 2.0))

    sliver, ledge = stack(78.0 - 0.02), stack(77.5)
    sag = facet_sag_mm(ledge, 128)  # 0.0235 mm
    annulus = 64 * np.sin(2 * np.pi / 128) * (78.0**2 - 77.5**2)  # the two 128-gons' areas' difference
    assert overhang_area(ledge, sliver_mm=sag) == pytest.approx(annulus, rel=1e-6)
    assert overhang_area(sliver) > 1e-3 > overhang_area(sliver, sliver_mm=sag)  # 0.02 mm wide: the facets' scale
    assert overhang_area(sliver, sliver_mm=0.01) > 1e-3  # wider than a smaller part's facets: an overhang there


def test_a_mesh_too_coarse_for_its_walls_fails_naming_segments(tmp_path):
    # 64 facets on a 156 mm flange sit 0.094 mm inside it: the STL's walls are that much thinner than designed
    with pytest.raises(HolderCheckError, match=r"cartridge's facets sit 0\.094 mm inside .*: raise segments"):
        write_holder(HolderParams(thread_diameter_mm=150.0, segments=64), tmp_path, step=False, renders=False)


@pytest.mark.parametrize("segments", [128, 256])
def test_the_largest_thread_passes_its_checks(tmp_path, segments):
    # the 150 mm thread (pitch and flange derived): its facets sit 0.0235 mm inside at 128 segments, and at 256 the
    # thread's section must be drawn as finely as the bore
    rep = write_holder(HolderParams(thread_diameter_mm=150.0, segments=segments), tmp_path, step=False,
                       renders=False)
    assert rep["checks"]["passed"] and rep["coupon_checks"]["passed"], (rep["checks"]["failing"],
                                                                         rep["coupon_checks"]["failing"])
    # the facets allowed for are the coarser of the circles' and the thread section's (120 points up to 128 segments)
    coarsest = 120 if segments == 128 else 256
    assert rep["checks"]["bodies"]["base"]["facet_sag_mm"] == pytest.approx(78.0 * (1 - np.cos(np.pi / coarsest)),
                                                                            abs=1e-4)


def test_a_layout_wider_than_a_common_bed_is_warned(tmp_path):
    """M127: base and cartridge side by side are wider than a 220 mm bed; the footprint stated is the STL's own
    (read back with trimesh), and the warning says to print them one at a time. The default M49 layout fits."""
    import trimesh

    big = write_holder(HolderParams(thread_diameter_mm=127.0), tmp_path / "big", step=False, renders=False)
    extents = trimesh.load(tmp_path / "big" / "holder.stl").extents
    np.testing.assert_allclose(big["print_footprint_mm"], extents, atol=0.01)
    assert extents[0] > 220 and any("more than a common 220 mm bed: print them one at a time" in w
                                    for w in big["warnings"])
    small = write_holder(HolderParams(), tmp_path / "small", step=False, renders=False)
    assert max(small["print_footprint_mm"][:2]) < 220 and small["warnings"] == []
