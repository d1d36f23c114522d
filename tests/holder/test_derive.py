"""The holder's dimensions that follow from the thread and the die: every common filter thread builds with no
other key (every check passes and every layer a slicer would print is supported); a given dimension that
conflicts is refused with the key to change and a value that builds."""

import functools
import math
import re

import numpy as np
import pytest

from holder_cad.build import assembly, build_parts
from holder_cad.checks import run_checks
from holder_cad.params import HolderError, HolderParams

# common photographic filter threads (mm) and the shipped mask sets' 12 mm × 12 mm die (the parameters' default)
FILTER_THREADS_MM = [25, 27, 28, 30.5, 34, 37, 39, 40.5, 43, 46, 49, 52, 55, 58, 62, 67, 72, 77, 82, 86, 95]
DERIVED = {"thread_pitch_mm", "thread_depth_mm", "thread_length_mm", "thread_clearance_mm", "flange_diameter_mm", "flange_height_mm",
           "washer_recess_mm"}
LAYER_MM = 0.2


def _standard_pitch(d: float) -> float:
    """Filter threads of 40.5 mm and smaller are generally M × 0.5, medium ones M × 0.75, 86 mm and up M × 1.0."""
    return 0.5 if d <= 40.5 else 0.75 if d < 86 else 1.0


def _least_thread_for_the_die(p: HolderParams) -> float:
    """The smallest thread (mm) whose cartridge holds the die's square-cornered washer recesses with a wall,
    from the part's stated layout: screw at the pocket edge + clearance + wall + pilot radius, recess reaching
    the washer radius + clearance past the screw; cartridge = thread radius − the thread's play − tooth − wall −
    clearance."""
    c, wall = p.clearance_mm, p.wall_mm
    rw = p.washer_diameter_mm / 2 + c
    screw = p.die_width_mm / 2 + c + wall + p.pilot_hole_mm / 2
    corner = math.hypot(screw + rw, rw)
    return 2 * (corner + wall + c + 0.2 + wall + 0.1)  # a 0.5 mm pitch's tooth (0.2 mm) and play (0.1 mm)


def _layers_supported(m) -> float:
    """Slice the body as a printer would (0.2 mm layers from the bed); every layer must lie within the one below
    grown by one layer height (45°), and the layers' volume must be the body's. Returns the layers' volume."""
    from manifold3d import JoinType

    b = m.bounding_box()
    zs = np.arange(b[2] + 0.37 * LAYER_MM, b[5], LAYER_MM)  # off the flat faces (all at multiples of 0.05 mm)
    below, volume = None, 0.0
    for z in zs:
        layer = m.slice(float(z))
        assert layer.area() > 0, f"empty layer at z = {z:.2f} mm"
        if below is not None:
            unsupported = (layer - below.offset(LAYER_MM + 0.02, JoinType.Round)).area()
            assert unsupported < 1e-3, f"{unsupported:.4f} mm² unsupported at z = {z:.2f} mm"
        below = layer
        volume += layer.area() * LAYER_MM
    return volume


@functools.lru_cache(maxsize=None)
def _build_and_check(**kw) -> dict:
    p = HolderParams(**kw)
    parts = build_parts(p)
    checks = run_checks(parts, assembly(parts, p), p, expected_bodies=2)
    assert checks["passed"], checks["failing"]
    for name, m in parts.items():
        assert _layers_supported(m) == pytest.approx(m.volume(), rel=0.02), name
    return checks


@pytest.mark.parametrize("thread", FILTER_THREADS_MM)
def test_common_filter_thread_builds_with_no_other_key(thread):
    least = _least_thread_for_the_die(HolderParams())
    if thread < least:  # the die and its washers cannot fit this thread's bore: refused with a step-up size
        with pytest.raises(HolderError, match=r"set thread_diameter_mm = ([\d.]+) or more") as err:
            HolderParams(thread_diameter_mm=thread)
        step_up = float(re.search(r"thread_diameter_mm = ([\d.]+)", str(err.value)).group(1))
        assert step_up == min(d for d in FILTER_THREADS_MM if d >= least)
        _build_and_check(thread_diameter_mm=step_up)
        return
    p = HolderParams(thread_diameter_mm=thread)
    assert set(p.derived) == DERIVED
    assert p.thread_pitch_mm == _standard_pitch(thread) and p.thread_depth_mm == pytest.approx(0.4 * p.thread_pitch_mm)
    checks = _build_and_check(thread_diameter_mm=thread)
    assert checks["bodies"]["base"]["bounding_box_mm"][3] == pytest.approx(p.flange_diameter_mm / 2, abs=0.01)


def test_pitch_follows_the_filter_standard_and_a_given_pitch_is_kept():
    for d, pitch in [(30.5, 0.5), (40.5, 0.5), (43, 0.75), (49, 0.75), (82, 0.75), (86, 1.0), (95, 1.0)]:
        p = HolderParams(thread_diameter_mm=d)
        assert (p.thread_pitch_mm, p.thread_depth_mm) == (pitch, pytest.approx(0.4 * pitch))
    p = HolderParams(thread_diameter_mm=49, thread_pitch_mm=0.5)
    assert (p.thread_pitch_mm, p.thread_depth_mm) == (0.5, pytest.approx(0.2))
    assert "thread_pitch_mm" not in p.derived and "thread_depth_mm" in p.derived


def test_the_shipped_holder_keeps_its_thread_and_height():
    p = HolderParams(thread_diameter_mm=49.0)  # the shipped scenes' only holder key
    assert (p.thread_pitch_mm, p.thread_depth_mm, p.flange_height_mm) == (0.75, 0.3, 6.0)
    assert p.flange_diameter_mm == 56.0
    kept = HolderParams(thread_diameter_mm=52.0, flange_diameter_mm=60.0)  # scenes/my_camera.toml
    # its chamfer meets the lens's crest radius at the thread's end, 0.17 mm higher than it met the printed crest,
    # and the lock-screw pilot holes above it (2 mm deep) need the next half millimetre: 6.08 mm → 6.5
    assert (kept.flange_diameter_mm, kept.flange_height_mm) == (60.0, 6.5) and "flange_diameter_mm" not in kept.derived


@pytest.mark.parametrize("kw, key", [
    ({"thread_diameter_mm": 52.0, "flange_diameter_mm": 57.0}, "flange_diameter_mm"),
    ({"thread_diameter_mm": 40.5, "flange_diameter_mm": 57.0, "flange_height_mm": 6.0}, "flange_height_mm"),
    # (the fix is a flange ~50 mm tall: a hole that long passes a 10° field, not the default 24°)
    ({"thread_diameter_mm": 49.0, "flange_diameter_mm": 200.0, "field_half_angle_deg": 10.0}, "flange_diameter_mm"),
    ({"thread_diameter_mm": 30.5, "thread_depth_mm": 0.3}, "thread_depth_mm"),
    ({"washer_diameter_mm": 4.0}, "washer_diameter_mm"),
    ({"clear_aperture_mm": 11.0}, "clear_aperture_mm"),
    ({"die_width_mm": 40.0, "die_height_mm": 40.0}, "thread_diameter_mm"),
])
def test_a_conflicting_key_is_named_with_a_value_that_builds(kw, key):
    with pytest.raises(HolderError) as err:
        HolderParams(**kw)
    msg = str(err.value)
    found = re.search(rf"set {key} = ([\d.]+)", msg)
    assert found, msg
    fixed = {**kw, key: float(found.group(1))}
    _build_and_check(**fixed)


def test_replace_derives_again_what_was_not_given():
    p = HolderParams()
    q = p.replace(thread_diameter_mm=40.5)
    assert (q.thread_pitch_mm, q.flange_diameter_mm) == (0.5, HolderParams(thread_diameter_mm=40.5).flange_diameter_mm)
    assert HolderParams(flange_diameter_mm=60.0).replace(thread_diameter_mm=52.0).flange_diameter_mm == 60.0


CUSTOM = "check the size on the lens's front ring or cap; a custom thread is built as given"


@pytest.mark.parametrize("kw, words", [
    ({"thread_diameter_mm": 49.3}, ["thread_diameter_mm 49.3 is no common filter thread (nearest 49 and 52 mm): "
                                    + CUSTOM]),
    ({"thread_diameter_mm": 33.3}, ["thread_diameter_mm 33.3 is no common filter thread (nearest 30.5 and 34 mm): "
                                    + CUSTOM]),
    ({"thread_pitch_mm": 0.6}, ["thread_pitch_mm 0.6 is no filter-thread pitch (0.5, 0.75, 1 mm): leave it out to "
                                "take the size's standard pitch, 0.75 mm"]),
    ({"thread_diameter_mm": 52.0}, []), ({"thread_diameter_mm": 30.5, "thread_pitch_mm": 0.5}, []),
    ({"mount": "slip", "thread_diameter_mm": 49.3}, []),  # no thread is cut
])
def test_a_thread_no_filter_has_is_built_and_warned(kw, words, tmp_path, capsys):
    """Filter threads come in a few dozen sizes (ISO 1222-style 0.5 / 0.75 / 1.0 mm pitches): a size or pitch off
    that list is most likely a misread lens. It is built as given, with a warning naming the nearest sizes."""
    import json

    from doefab.cli import main

    p = HolderParams(**kw)
    assert p.warnings == words
    sets = [a for k, v in kw.items() for a in ("--set", f"{k}={v}")]
    assert main(["holder", "--out", str(tmp_path / "h"), "--no-step", "--no-renders", *sets]) == 0
    err = capsys.readouterr().err
    assert [line[len("warning: "):] for line in err.splitlines() if line.startswith("warning: ")] == words
    assert json.loads((tmp_path / "h" / "holder.json").read_text())["warnings"] == words


def test_a_refusal_offers_fixes_that_build_or_says_what_follows():
    """A 10 mm die: shrinking the clear aperture to fit it runs the washers' recesses into the keyed chamfer, so
    only the die that builds is offered. A washer too small for a 31 mm die on M52: its fix then needs a larger
    thread, which the refusal says at once; taking both builds."""
    with pytest.raises(HolderError) as err:
        HolderParams(die_width_mm=10.0, die_height_mm=10.0)
    msg = str(err.value)
    assert "set die_width_mm and die_height_mm to 12 or more" in msg and "clear_aperture_mm = 7.12" not in msg
    with pytest.raises(HolderError):
        HolderParams(die_width_mm=10.0, die_height_mm=10.0, clear_aperture_mm=7.12)  # the fix no longer offered
    HolderParams(die_width_mm=12.0, die_height_mm=12.0)
    kw = {"thread_diameter_mm": 52.0, "die_width_mm": 31.0, "die_height_mm": 31.0, "clearance_mm": 1.0,
          "die_chamfer_mm": 7.2}
    with pytest.raises(HolderError, match=r"set washer_diameter_mm = 7\.5 or more \(then: .*set thread_diameter_mm "
                                          r"= 58 or more"):
        HolderParams(**kw)
    HolderParams(**{**kw, "washer_diameter_mm": 7.5, "thread_diameter_mm": 58.0})
