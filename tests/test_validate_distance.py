"""A distance that may lie at infinity, read from and written to files in one way (``doefab.validate``): a scene's
focus and planes, a design record, a lab's recordings file take the same spellings."""

import json
import math

import numpy as np
import pytest

from doefab.errors import DoefabError
from doefab.validate import distance_or_inf, distance_record


@pytest.mark.parametrize("value,expected", [
    (2, 2.0), (0.5, 0.5), (np.float32(1.5), 1.5), (np.int64(3), 3.0), (math.inf, math.inf), ("inf", math.inf),
    (" Infinity ", math.inf), ("INF", math.inf), (-1.0, -1.0)])
def test_distance_or_inf_reads_numbers_and_infinity(value, expected):
    assert distance_or_inf(value) == expected


@pytest.mark.parametrize("value", [True, False, "far", "", "-inf", "2", math.nan, None, [2.0]])
def test_distance_or_inf_refuses_anything_else(value):
    assert distance_or_inf(value) is None


@pytest.mark.parametrize("z", [2.0, 1e-3, math.inf, np.float64(0.7)])
def test_distance_record_round_trips_through_json(z):
    text = json.dumps(distance_record(z), allow_nan=False)  # JSON proper: no Infinity token
    assert distance_or_inf(json.loads(text)) == z


@pytest.mark.parametrize("z", [-math.inf, math.nan])
def test_distance_record_refuses_what_is_no_distance(z):
    with pytest.raises(DoefabError, match="number or \\+inf"):
        distance_record(z)


@pytest.mark.parametrize("word", ["inf", "Infinity"])
def test_camera_and_design_records_read_infinity_in_either_word(word):
    """A camera record (``Camera.from_dict``) and a design record's planes read the words a scene takes."""
    import doefab
    from doefab.design.design import _check_meta

    d = doefab.Camera(focus_distance=math.inf).to_dict()
    assert d["focus_distance_m"] == "inf"
    assert doefab.Camera.from_dict({**d, "focus_distance_m": word}).focus_distance == math.inf
    meta = _design_meta()
    assert _check_meta({**meta, "depths_m": [2.0, word]}, "design.json")["depths_m"] == [2.0, math.inf]


def _design_meta() -> dict:
    import io
    from pathlib import Path

    packed = Path(__file__).resolve().parents[1] / "doefab" / "designs" / "streak.npz"
    with np.load(io.BytesIO(packed.read_bytes()), allow_pickle=False) as z:
        return json.loads(z["design_json"].tobytes())


def _lab_depth(tmp_path, value: str):
    from doefab.lab.recordings import load_recordings

    (tmp_path / "r.toml").write_text(f'design = "d"\n[[psf]]\nhalf = "coded"\nview = "coded"\ndepth_m = {value}\n'
                                     f'wavelength_nm = 550\nframes = "a.png"\n')
    try:
        load_recordings(tmp_path / "r.toml")
    except DoefabError as exc:
        return str(exc)
    return ""


@pytest.mark.parametrize("value,accepted", [("inf", True), ('"inf"', True), ('"Infinity"', True), ("-inf", False),
                                            ('"far"', False), ("0", False), ("2.5", True)])
def test_lab_recordings_take_the_scene_spellings(tmp_path, value, accepted):
    """The recordings file's ``depth_m`` takes infinity as a scene does (TOML's inf or the word)."""
    msg = _lab_depth(tmp_path, value)
    assert ("depth_m" not in msg) == accepted, msg


def _scene_error(tmp_path, body: str) -> str:
    from doefab.pipeline.scene import load_scene

    (tmp_path / "s.toml").write_text(body)
    try:
        load_scene(tmp_path / "s.toml")
    except DoefabError as exc:
        return str(exc)
    return ""


def test_a_plane_at_infinity_spelled_twice_is_one_plane_twice(tmp_path):
    """inf and "inf" in one list of planes are the same plane: refused as listed twice, with the list once."""
    msg = _scene_error(tmp_path, 'task = "depth"\n[optics]\ndepths_m = [1.0, inf, "Infinity"]\n')
    assert "holds inf more than once ('Infinity' and inf are one plane)" in msg and "e.g. [1.0, inf]" in msg, msg


@pytest.mark.parametrize("key,value,says", [
    ("camera.focus_distance_m", '"far"', "must be a number or inf, got 'far'"),
    ("optics.depths_m", '[1.0, "far"]', "each item must be within 0.001–1e+06 m or inf")])
def test_a_key_that_takes_infinity_says_so_when_refusing(tmp_path, key, value, says):
    section, name = key.split(".")
    msg = _scene_error(tmp_path, f'task = "hdr"\n[{section}]\n{name} = {value}\n')
    assert says in msg, msg
