"""The holder passes the light of the whole field to the DOE: the hole in front of the die flares toward the scene,
so that rays through any point of the DOE's clear aperture (its chrome stop, on the patterned face), at any angle up
to the field's half-angle and refracted by Snell's law inside the die, miss the printed part. Checked on the built
mesh by sections, against ray envelopes computed here, and by the holder's own ray check, which must also fail."""

import math

import numpy as np
import pytest
import trimesh

from holder_cad.build import assembly, build_parts
from holder_cad.checks import aperture_clear
from holder_cad.mesh import to_trimesh
from holder_cad.params import HolderError, HolderParams

N_SILICA = 1.458  # fused silica at 550 nm, the shipped DOEs' substrate


def _envelope_mm(p: HolderParams, height_mm: float, angle_deg: float) -> float:
    """Radius (mm) of the light of a field point at ``angle_deg`` through the clear aperture, ``height_mm`` in front
    of the DOE's patterned face: straight through the die at the refracted angle, then in air."""
    t = math.radians(angle_deg)
    inside = math.asin(math.sin(t) / N_SILICA)
    glass = min(height_mm, p.die_thickness_mm)
    return p.clear_aperture_mm / 2 + glass * math.tan(inside) + max(height_mm - p.die_thickness_mm, 0.0) * math.tan(t)


def _hole_radius_mm(cartridge: trimesh.Trimesh, z: float) -> float:
    """The radius of the largest circle about the axis clear of the cartridge's section at height z (print
    orientation): the nearest section vertex or edge to the axis."""
    sec = cartridge.section(plane_origin=(0, 0, z), plane_normal=(0, 0, 1))
    pts = np.asarray(sec.vertices)[:, :2]
    return float(np.hypot(*pts.T).min())


@pytest.mark.parametrize("kw", [{}, {"mount": "slip"}, {"field_half_angle_deg": 12.0, "die_thickness_mm": 1.5}])
def test_the_hole_clears_the_light_of_the_whole_field(kw):
    p = HolderParams(segments=256, **kw)
    cart = to_trimesh(build_parts(p)["cartridge"])
    face = cart.bounds[1, 2] - p.washer_recess_mm  # the DOE's patterned face, in print orientation (scene below)
    for z in np.linspace(0.05, face - p.die_thickness_mm - 0.05, 12):
        got, need = _hole_radius_mm(cart, z), _envelope_mm(p, face - z, p.field_half_angle_deg)
        assert got >= need + 0.09 - 0.01, (z, got, need)  # FLARE_SLACK_MM of clearance, less the facets' sag
    # the old straight hole of the aperture's radius plus margin does not: its walls cut the field's edge
    assert _envelope_mm(p, face, p.field_half_angle_deg) > p.clear_aperture_mm / 2 + p.aperture_margin_mm


def test_the_ray_check_passes_the_field_and_fails_beyond_it():
    p = HolderParams(segments=128)
    asm = assembly(build_parts(p), p)
    ray = dict(radius_mm=p.clear_aperture_mm / 2, rings=6, z_mm=p.washer_recess_mm, die_mm=p.die_thickness_mm)
    assert aperture_clear(asm, angle_deg=p.field_half_angle_deg, **ray) == 0
    assert aperture_clear(asm, angle_deg=p.field_half_angle_deg + 6.0, **ray) > 0
    straight = HolderParams(segments=128, field_half_angle_deg=0.0)  # a hole that does not flare
    assert aperture_clear(assembly(build_parts(straight), straight), angle_deg=10.0, **ray) > 0


@pytest.mark.parametrize("kw, words", [
    ({"field_half_angle_deg": 50.0}, "field_half_angle_deg must be a number of degrees in 0–45"),
    ({"field_half_angle_deg": "wide"}, "field_half_angle_deg must be"),
    ({"field_half_angle_deg": 44.0}, "smaller field_half_angle_deg"),  # its light spreads past the die's ledge
])
def test_a_field_the_holder_cannot_pass_is_refused(kw, words):
    with pytest.raises(HolderError, match=words):
        HolderParams(**kw)


def test_a_flare_that_outgrows_the_cartridge_is_refused_with_a_field_that_builds():
    import re

    tall = {"thread_diameter_mm": 37.0, "die_width_mm": 14.0, "die_height_mm": 14.0, "flange_height_mm": 14.0}
    with pytest.raises(HolderError, match=r"^field_half_angle_deg \(40°\).*less than wall_mm") as e:
        HolderParams(field_half_angle_deg=40.0, **tall)
    widest = float(re.search(r"set field_half_angle_deg = ([\d.]+) or less", str(e.value)).group(1))
    assert HolderParams(field_half_angle_deg=widest, **tall).aperture_flare_radius_mm > 0  # builds
    with pytest.raises(HolderError, match="^field_half_angle_deg"):
        HolderParams(field_half_angle_deg=widest + 0.2, **tall)
