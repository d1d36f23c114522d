"""The fit-test coupon: the base's own thread, bore and lens-side seat under a narrow grip rim, for much less plastic
than the base, printable without supports."""

import pytest

from holder_cad.build import build_parts
from holder_cad.mesh import build_manifold
from holder_cad.params import HolderParams
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
