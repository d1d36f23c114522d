"""The fit-test coupon: the base's own thread, bore and lens-side seat under a narrow grip rim, for much less plastic
than the base, printable without supports."""

import pytest

from holder_cad.build import build_parts
from holder_cad.mesh import build_manifold
from holder_cad.bounds import fit_bounds
from holder_cad.params import HolderError, HolderParams
from holder_cad.recipe import coupon_bodies

from tests.holder.test_derive import _layers_supported


@pytest.mark.parametrize("thread", [49.0, 77.0])
def test_coupon_ring_is_the_bases_thread_for_half_the_plastic(thread):
    p = HolderParams(thread_diameter_mm=thread)
    base = build_parts(p)["base"]
    ring = build_manifold(next(b for b in coupon_bodies(p) if b.name == "coupon_ring"), p.segments)
    # the thread and the bore: the same cross-sections at every height of the thread, below the flange's chamfer
    for z in (0.3, 0.5 * p.thread_length_mm, p.thread_length_mm - 0.5):
        assert ring.slice(z).area() == pytest.approx(base.slice(z).area(), rel=1e-6), z
    # the grip rim: a flat lens-side seat round the thread, 2 mm beyond it, as the base's flange is
    b = ring.bounding_box()
    assert b[3] == pytest.approx(p.thread_major_radius_mm + 2.0, abs=0.01) and b[2] == 0.0
    assert ring.volume() < 0.5 * base.volume()
    # every 0.2 mm layer rests on the one below (45°); their volume is the ring's to within one layer (the last
    # one overshoots its top)
    assert abs(_layers_supported(ring) - ring.volume()) < 0.2 * ring.slice(b[5] - 0.1).area()


@pytest.mark.parametrize("kw", [{}, {"thread_diameter_mm": 77.0}, {"thread_diameter_mm": 30.5, "die_width_mm": 10.0,
                                                                   "die_height_mm": 10.0, "clear_aperture_mm": 6.0,
                                                                   "washer_diameter_mm": 5.7}])
def test_thread_starts_on_the_bed_with_a_lead_in(kw):
    """Where the thread meets the bed its teeth are cut back to just inside the root (the first layer's squash
    stays there), growing 0.8 mm per mm of height (steeper than the 45° limit) to the full tooth: the base's and
    the coupon's alike."""
    import numpy as np

    p = HolderParams(**kw)
    base = build_parts(p)["base"]
    ring = build_manifold(next(b for b in coupon_bodies(p) if b.name == "coupon_ring"), p.segments)

    def reach(m, z):  # the outermost radius of the section at height z (mm)
        pts = np.concatenate([np.asarray(q) for q in m.slice(z).to_polygons()])
        return np.hypot(pts[:, 0], pts[:, 1]).max()

    root, major = p.thread_root_radius_mm, p.thread_major_radius_mm
    for m in (base, ring):
        for z in (0.02, 0.1, 0.2):  # on the cone from 0.05 mm inside the root
            assert reach(m, z) == pytest.approx(root - 0.05 + 0.8 * z, abs=2e-3), z
        assert reach(m, (p.thread_depth_mm + 0.05) / 0.8 + 0.05) == pytest.approx(major, abs=1e-3)  # full tooth


@pytest.mark.parametrize("thread", [49.0, 95.0])
def test_thread_bears_two_full_turns_between_its_lead_in_and_the_flange(thread):
    """Measured on the base's mesh: from where the lead-in reaches the full tooth to where the flange's chamfer
    starts to fill the groove there are at least two turns of the pitch, for the default length of each pitch (a
    1.0 mm pitch needs a longer thread than 2.5 mm); the same as the fit bound reports, and a thread too short for
    two is refused with the length that gives them."""
    import numpy as np

    p = HolderParams(thread_diameter_mm=thread)
    base = build_parts(p)["base"]
    root, major = p.thread_root_radius_mm, p.thread_major_radius_mm

    def radii(z):  # the section's outer contour at height z: (innermost, outermost) radius (mm)
        pts = np.concatenate([np.asarray(q) for q in base.slice(z).to_polygons()])
        r = np.hypot(pts[:, 0], pts[:, 1])
        r = r[r > root - 0.3]  # not the bore
        return r.min(), r.max()

    zs = np.arange(0.005, p.thread_length_mm, 0.005)
    full = next(z for z in zs if radii(z)[1] > major - 1e-3)  # the lead-in's top
    filled = next(z for z in zs if radii(z)[0] > root + 1e-3)  # the chamfer reaches the groove's bottom
    turns = (filled - full) / p.thread_pitch_mm
    assert turns >= 2.0
    bound = next(b for b in fit_bounds(p) if b["quantity"] == "thread_full_tooth_turns")
    assert bound["value"] == pytest.approx(turns, abs=0.03) and bound["ok"]
    if thread == 95.0:
        assert p.thread_length_mm > 2.5
        with pytest.raises(HolderError, match=r"thread_full_tooth_turns.*set thread_length_mm between "
                                              f"{p.thread_length_mm:g} and"):
            HolderParams(thread_diameter_mm=thread, thread_length_mm=p.thread_length_mm - 0.1)
