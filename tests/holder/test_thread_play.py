"""The printed thread fits the lens's ISO metric filter thread: with its derived play the printed tooth (45°
flanks) is no wider than the female thread's 60° groove where they meet, and it still engages; a play that jams
the tooth or leaves too little engaged is refused. The ISO basic profile is computed here from its definition
(H = √3/2·P; the internal thread's minor diameter D1 = D − 2·(5/8)·H; its groove 3/4·P wide there)."""

import math

import pytest

from holder_cad.params import HolderError, HolderParams
from holder_cad.recipe import thread_section


def _groove_and_tooth(p: HolderParams) -> tuple[float, float, float]:
    """(the female groove's width at D1, the printed tooth's width at that radius, the radial engagement), mm."""
    pitch, d = p.thread_pitch_mm, p.thread_diameter_mm
    h = math.sqrt(3) / 2 * pitch
    r1 = d / 2 - 5 / 8 * h  # the internal thread's minor radius
    groove = pitch - pitch / 4  # its crest flat is P/4 wide: the space between its crests 3P/4
    r = thread_section(p, 720)
    crest = float(max(math.hypot(x, y) for x, y in r))  # the printed thread's outer radius, from its section
    depth = crest - r1  # how far the printed tooth reaches past the female crests
    crest_flat = (pitch - 2 * p.thread_depth_mm) / 2
    tooth = crest_flat + 2 * depth  # 45° flanks widen it by the depth on each side
    return groove, tooth, depth


@pytest.mark.parametrize("thread, depth", [(30.5, None), (49.0, None), (95.0, None), (49.0, 0.2)])
def test_the_derived_play_clears_the_groove_and_engages(thread, depth):
    p = HolderParams(thread_diameter_mm=thread, thread_depth_mm=depth)  # 0.2 mm: a shallower tooth, a wider crest
    groove, tooth, depth = _groove_and_tooth(p)
    # a printed tooth needs more than geometric clearance: at 0.1 mm layers its layers' edges stand up to 0.05 mm
    # proud of each 45° flank (both at once: 0.1 mm), and the print is good to about ±0.05 mm
    assert groove - tooth >= 0.15 - 1e-9
    basic = 5 / 8 * math.sqrt(3) / 2 * p.thread_pitch_mm
    assert depth >= 0.25 * basic  # 29–46 % of the basic depth engaged


@pytest.mark.parametrize("play, words", [(0.10, "between 0.1625 and"), (0.40, "between 0.1625 and")])
def test_a_play_that_jams_or_barely_engages_is_refused(play, words):
    with pytest.raises(HolderError, match=f"thread_clearance_mm = {play:.3g} mm is outside.*{words}"):
        HolderParams(thread_clearance_mm=play)
    hp = HolderParams()
    ok = HolderParams(thread_clearance_mm=0.25)  # looser: a third of the depth engaged
    assert _groove_and_tooth(ok)[1] < _groove_and_tooth(hp)[1]


@pytest.mark.parametrize("thread", [30.5, 49.0, 95.0])
def test_the_base_seats_on_the_filter_face(thread):
    """Read on the base's mesh: below the thread's end (the lens's filter face) every section leaves a groove open
    to inside the lens's crest radius (the ISO internal thread's minor radius D1/2), so the lens's crest passes; just
    above it the flange's chamfer is wider than that radius. The base screws in until its flange meets the filter
    face — the chamfer had met the crest a tooth's engagement short of it (0.09, 0.17 and 0.25 mm here)."""
    import numpy as np

    from holder_cad.build import build_parts

    p = HolderParams(thread_diameter_mm=thread)
    base = build_parts(p)["base"]
    r1 = thread / 2 - 5 / 8 * math.sqrt(3) / 2 * p.thread_pitch_mm  # the internal thread's minor radius

    def innermost(z):  # the smallest radius of the section's outer contour at height z (the bore left out)
        pts = np.concatenate([np.asarray(q) for q in base.slice(z).to_polygons()])
        r = np.hypot(pts[:, 0], pts[:, 1])
        return float(r[r > p.bore_radius_mm + 0.5].min())

    t = p.thread_length_mm
    for z in np.linspace(t - 0.4, t - 0.005, 12):
        assert innermost(z) <= r1 + 1e-3, z
    assert innermost(t + 0.05) > r1


def test_coarser_layers_derive_more_flank_clearance_or_are_refused_with_one_that_works():
    """Each layer's edge stands up to half a layer proud of a 45° flank, both flanks at once: the clearance the
    groove keeps is the layer height plus the print's ±0.05 mm. At 0.2 mm layers M49 × 0.75 keeps 0.25 mm and still
    engages a quarter of its basic depth; M30.5 × 0.5 cannot, and is refused with the coarsest layer that can."""
    p = HolderParams(layer_mm=0.2)
    groove, tooth, depth = _groove_and_tooth(p)
    assert groove - tooth == pytest.approx(0.25, abs=1e-4)  # read from the section (float32 vertices)
    assert depth >= 0.25 * 5 / 8 * math.sqrt(3) / 2 * p.thread_pitch_mm
    with pytest.raises(HolderError, match=r"print the thread at layer_mm = 0\.13 or less"):
        HolderParams(thread_diameter_mm=30.5, layer_mm=0.2)
    fine = HolderParams(thread_diameter_mm=30.5, layer_mm=0.13)
    groove, tooth, depth = _groove_and_tooth(fine)
    assert groove - tooth >= 0.18 - 1e-6 and depth >= 0.25 * 5 / 8 * math.sqrt(3) / 2 * 0.5
