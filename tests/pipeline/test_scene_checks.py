"""What ``load_scene`` checks before any stage runs: keys that set the same quantity, substrate names (one
resolver with the API), every item of a list key, the tolerance budget the scene names, a byte-order mark; and
the scene keys ``doctor`` names where a sampling check fails."""

import itertools

import pytest

from doefab.errors import DoefabError
from doefab.optics.materials import SUBSTRATES, material_by_name, substrate_name
from doefab.pipeline.scene import SAME_QUANTITY, load_scene
from doefab.pipeline.scenekeys import KEYS

CAMERA_VALUES = {"focal_length_mm": 35.0, "sensor_distance_mm": 50.5, "sensor_distance_m": 0.0505,
                 "aperture_diameter_mm": 8.0, "f_number": 4.0}


def _scene(tmp_path, text: str, task: str = "hdr"):
    p = tmp_path / "scene.toml"
    p.write_text(f'task = "{task}"\n{text}\n')
    return p


@pytest.mark.parametrize("a, b", [pair for group, _ in SAME_QUANTITY for pair in itertools.combinations(group, 2)])
def test_two_keys_for_one_quantity_are_refused(tmp_path, a, b):
    """focal_length_mm with sensor_distance_m (issue 37, row 3) is refused as the sensor_distance_mm pair is,
    both keys and their values named; either key alone is accepted."""
    text = f"[camera]\n{a} = {CAMERA_VALUES[a]}\n{b} = {CAMERA_VALUES[b]}\n"
    with pytest.raises(DoefabError) as exc:
        load_scene(_scene(tmp_path, text))
    msg = str(exc.value)
    assert f"camera.{a} = {CAMERA_VALUES[a]}" in msg and f"camera.{b} = {CAMERA_VALUES[b]}" in msg, msg
    assert "keep one of them" in msg
    for key in (a, b):
        assert load_scene(_scene(tmp_path, f"[camera]\n{key} = {CAMERA_VALUES[key]}\n")).camera == {
            key: CAMERA_VALUES[key]}


@pytest.mark.parametrize("name", ["Fused Silica", "n-bk7", "caf2", "fused_silica", "SAPPHIRE", "pmma", " N_BK7 "])
def test_a_substrate_name_in_any_case_is_the_one_the_api_resolves(tmp_path, name):
    """Scene files and ``material_by_name`` take the same names (issue 37, row 10): the scene's camera gets the
    substrate the API gives."""
    from doefab.pipeline.system import scene_camera

    scene = load_scene(_scene(tmp_path, f'[fabrication]\nmaterial = "{name}"'))
    assert scene_camera(scene).material is material_by_name(name) is SUBSTRATES[substrate_name(name)].material


def test_an_unknown_substrate_is_refused_with_the_names_a_scene_can_use(tmp_path):
    with pytest.raises(DoefabError) as exc:
        load_scene(_scene(tmp_path, '[fabrication]\nmaterial = "quartz"'))
    msg = str(exc.value)
    assert "fabrication.material" in msg and "'quartz'" in msg and all(repr(n) in msg for n in SUBSTRATES)
    assert "doefab.Material" not in msg  # the API's way to another substrate is not a scene's


LIST_KEYS = [k for k in KEYS if k.kind == "list"]


def _item(key):
    """A valid item of a list key."""
    return f'"{key.choices[0]}"' if key.item == "choice" else f"{(key.lo * key.hi) ** 0.5:.4g}"


def _bad_items(key):
    """Items outside what the key's items take: below and above its range, NaN, a word it does not know."""
    if key.item == "choice":
        return ['"d"', '"nonsense"', "1"]
    return [f"{key.lo / 10:g}", f"{key.hi * 10:g}", "nan", '"far"']


def _set(key, value: str) -> str:
    return f"{key.name} = {value}" if not key.section else f"[{key.section}]\n{key.name} = {value}"


def _list_cases():
    out = []
    for key in LIST_KEYS:
        name = f"{key.section}.{key.name}".lstrip(".")
        out.append(pytest.param(key, _item(key), f"{name} must be a list: write [{_item(key)}]",
                                id=f"{name}-not-a-list"))
        out.append(pytest.param(key, "[]", f"{name} is empty", id=f"{name}-empty"))
        out.append(pytest.param(key, f"[{_item(key)}, {_item(key)}]", "more than once", id=f"{name}-twice"))
        out += [pytest.param(key, f"[{bad}]", f"{name} holds", id=f"{name}-item-{bad}") for bad in _bad_items(key)]
    return out


@pytest.mark.parametrize("key, value, needle", _list_cases())
def test_every_list_key_checks_its_type_each_item_and_repeats(tmp_path, key, value, needle):
    """Issue 37, row 11, for every list key of the table: not a list ("stages = "design""), empty, an item twice,
    an item outside the key's range (each item is checked as the key's unit and range say)."""
    with pytest.raises(DoefabError) as exc:
        load_scene(_scene(tmp_path, _set(key, value), task="depth"))
    msg = str(exc.value)
    assert needle in msg, msg
    assert "unknown stage 'd'" not in msg


def test_the_user_trials_lists_are_refused_with_their_fix(tmp_path):
    text = "[optics]\nwavelengths_nm = [550, 550, 600]\ndepths_m = [1e-9, 1, 2, 2]"
    with pytest.raises(DoefabError) as exc:
        load_scene(_scene(tmp_path, text, task="depth"))
    msg = str(exc.value)
    assert "optics.wavelengths_nm holds 550 more than once: list each item once, e.g. [550, 600]" in msg
    assert "optics.depths_m holds 1e-09: each item must be within 0.001–1e+06 m" in msg
    assert "optics.depths_m holds 2 more than once" in msg


def test_a_bad_budget_is_refused_with_the_scene(tmp_path):
    """The budget a scene names is checked with the scene (issue 37, row 4): every problem listed, with the key
    tolerance.budget, before any stage runs."""
    (tmp_path / "tight.toml").write_text("[etch]\nsystematic_sigma_percent = -3\n[spec.hdr]\npsf_metric_min = 5.0\n")
    with pytest.raises(DoefabError) as exc:
        load_scene(_scene(tmp_path, '[tolerance]\nbudget = "tight.toml"'))
    msg = str(exc.value)
    assert "2 problems:\n  - tolerance.budget" in msg and msg.count("\n  - ") == 2  # one problem to a line
    assert "tolerance.budget tight.toml: etch.systematic_sigma_percent = -3 is outside 0–50" in msg
    assert "tolerance.budget tight.toml: spec.hdr.psf_metric_min = 5.0 is outside 0–1" in msg
    # the shipped budget's name in another case is the shipped budget, as --budget Default is at the CLI
    assert load_scene(_scene(tmp_path, '[tolerance]\nbudget = " Default"')).budget_path() is None
    (tmp_path / "tight.toml").write_text("[etch]\nsystematic_sigma_percent = 3\n")
    assert load_scene(_scene(tmp_path, '[tolerance]\nbudget = "tight.toml"')).budget_path() == tmp_path / "tight.toml"


def test_the_shipped_budget_has_one_name_for_scenes_the_cli_and_the_api(tmp_path, monkeypatch):
    """``default`` in any case names the shipped budget in a scene, at ``--budget`` (tolerance and diagnose both
    call ``load_budget``) and in ``load_budget``; a file of that name beside the scene, or in the working directory,
    is read as the file it is."""
    from doefab.io import read_toml
    from doefab.tolerance.errors import DEFAULT_BUDGET, load_budget, names_default_budget

    shipped = read_toml(DEFAULT_BUDGET, "budget")
    assert {k: v for k, v in load_budget("DEFAULT").items() if k != "defaults_used"} == shipped
    assert load_budget("default")["defaults_used"] == []
    monkeypatch.chdir(tmp_path)
    (tmp_path / "Default").write_text("[etch]\nsystematic_sigma_percent = 7\n")
    assert not names_default_budget("Default") and names_default_budget("default")  # a case-sensitive file system
    assert load_budget("Default")["etch"]["systematic_sigma_percent"] == 7
    assert shipped["etch"]["systematic_sigma_percent"] != 7
    assert load_scene(_scene(tmp_path, '[tolerance]\nbudget = "Default"')).budget_path() == tmp_path / "Default"


def test_a_scene_and_its_budget_saved_with_a_byte_order_mark_load(tmp_path):
    """Issue 37, row 12: some editors save UTF-8 with a byte-order mark; it is not part of the TOML."""
    from doefab.tolerance.errors import load_budget

    (tmp_path / "b.toml").write_bytes("\ufeff[etch]\nsystematic_sigma_percent = 2.0\n".encode())
    p = tmp_path / "scene.toml"
    p.write_bytes('\ufefftask = "depth"\n[tolerance]\nbudget = "b.toml"\n'.encode())
    assert load_scene(p).task == "depth"
    assert load_budget(tmp_path / "b.toml")["etch"]["systematic_sigma_percent"] == 2.0


@pytest.mark.parametrize("task, bands, stages, weights, refused", [
    ("depth", "[1064]", None, "train", True),              # a monochrome NIR design: the RGB network cannot take it
    ("hdr", "[486, 589, 656]", None, "shipped-anyway", True),  # blue first: the 486 nm PSF would blur the red channel
    ("hdr", "[656, 486, 589]", None, "train", True),       # red first, but green and blue swapped
    ("hdr", "[656, 589, 486, 450]", None, "train", True),
    ("depth", "[1064]", '["design", "masks", "holder", "tolerance"]', "train", False),  # no network: designed alone
    ("depth", "[1064]", None, None, False),  # the shipped networks skip another design: nothing reads its bands
    ("hdr", "[630, 532, 450]", None, "train", False),
    ("hyperspectral", "[450, 500, 550, 600, 650]", None, "train", False),  # spectra take any bands
])
def test_a_network_route_needs_one_band_per_rgb_channel(tmp_path, task, bands, stages, weights, refused):
    """doctor and run (both ``resolve``) refuse an RGB application's bands that are not three, longest first, when
    the scene trains or evaluates networks on its design; without them the design goes ahead on its bands."""
    from doefab.pipeline.system import resolve

    text = ((f"stages = {stages}\n" if stages else "") + f"[optics]\nwavelengths_nm = {bands}\n"
            + (f'[reconstruction]\nweights = "{weights}"\n' if weights else ""))
    scene = load_scene(_scene(tmp_path, text, task))
    if not refused:
        got = [w * 1e9 for w in resolve(scene).settings["wavelengths_m"]]
        assert got == pytest.approx([float(b) for b in bands.strip("[]").split(",")])
        return
    with pytest.raises(DoefabError) as exc:
        resolve(scene)
    msg = str(exc.value)
    assert "optics.wavelengths_nm" in msg and "three bands" in msg and "longest first (red, green, blue" in msg, msg
    assert f"got {bands}" in msg and 'leave "reconstruction" out of stages' in msg
