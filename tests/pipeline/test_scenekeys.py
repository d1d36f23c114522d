"""The scene-key table: its template loads and resolves for every task, the CLI writes it without replacing a
file, and the reference table lists every key."""

import tomllib

import pytest

from doefab.cli import main
from doefab.pipeline.scene import load_scene
from doefab.applications import has
from doefab.pipeline.scenekeys import KEYS, key_table_markdown, template


@pytest.mark.parametrize("task", ["hdr", "hyperspectral", "depth"])
def test_template_is_a_valid_scene_for_another_camera(task, tmp_path):
    from doefab.pipeline.system import resolve

    p = tmp_path / f"{task}.toml"
    p.write_text(template(task))
    res = resolve(load_scene(p))
    cam = res.camera
    # the template's camera: 35 mm f/4, 3.76 µm pixels, a 4 µm DOE pitch
    assert cam.sensor_pitch == pytest.approx(3.76e-6)
    assert cam.doe_pitch == pytest.approx(4e-6)
    assert cam.aperture_diameter == pytest.approx(35e-3 / 4, rel=1e-9)
    assert res.custom_camera and not res.reuse
    assert res.warnings == ()  # a fresh template is consistent with itself (doctor and run warn of nothing)


@pytest.mark.parametrize("task", ["hdr", "hyperspectral", "depth"])
def test_template_names_every_key_of_its_task_with_its_unit(task):
    """Every key the task's scenes take, and none of another task's (``load_scene`` refuses those)."""
    text = template(task)
    raw = tomllib.loads(text)
    for k in KEYS:
        if not k.section or k.name in ("preset", "sensor_distance_m"):
            continue
        assert (f"{k.name} = " in text) == (not k.only or has(task, k.only)), k.name
    assert raw["camera"]["focal_length_mm"] == 35.0
    table = key_table_markdown()
    assert all(f"`{k.section}.{k.name}`" in table for k in KEYS if k.section)


def test_scene_new_writes_once_and_refuses_to_replace(tmp_path, capsys):
    out = tmp_path / "mine.toml"
    assert main(["scene", "new", "--task", "depth", "--out", str(out)]) == 0
    assert load_scene(out).task == "depth"
    before = out.read_text()
    assert main(["scene", "new", "--task", "hdr", "--out", str(out)]) == 2
    assert out.read_text() == before
    assert "exists" in capsys.readouterr().err
    assert main(["scene", "new", "--task", "hdr", "--out", str(tmp_path / "mine.txt")]) == 2
    assert main(["scene", "new", "--task", "hdr", "--out", str(tmp_path / "no" / "x.toml")]) == 2


@pytest.mark.parametrize("task, key, value, param, want", [
    ("hdr", "streak_arm_px", 30, "arm_px", 30),
    ("hdr", "streak_band_px", 2, "band_px", 2),
    ("hyperspectral", "grating_period_um", 108.0, "period_m", 108e-6),
    ("hyperspectral", "grating_box_px", 2, "box_px", 2),
    ("depth", "ring_max_px", 20.0, "ring_max_px", 20.0),
    ("depth", "ring_width_px", 2.5, "delta_px", 2.5),
    ("depth", "ring_law", '"seed"', "ring_law", "seed"),
])
def test_each_geometry_key_reaches_the_task(tmp_path, task, key, value, param, want):
    """A [design] geometry key (its unit in its name) sets the task parameter it names, in SI units, and makes the
    scene's design differ from the committed one."""
    from doefab.pipeline.scene import load_scene
    from doefab.pipeline.system import resolve

    p = tmp_path / "s.toml"
    p.write_text(f'task = "{task}"\n[design]\n{key} = {value}\n')
    res = resolve(load_scene(p))
    got = getattr(res.task, param)
    assert got == (pytest.approx(want) if isinstance(want, float) else want)
    assert not res.reuse


def _cell(k) -> str:
    """The "unit and range, or values" cell of a key's row in the key table."""
    name = f"{k.section}.{k.name}" if k.section else k.name
    row = next(r for r in key_table_markdown().splitlines() if r.startswith(f"| `{name}` |"))
    return row.split(" | ")[1]


@pytest.mark.parametrize("k", KEYS, ids=[f"{k.section}.{k.name}" for k in KEYS])
def test_every_key_prints_its_unit_and_range(k):
    """``doefab scene keys`` and the template of ``scene new`` (issue 37, row 21): a numeric key shows its unit
    (or "no unit") and its range, a list key what each item takes; no cell or note is left with a bare ", 0.5–64"
    or "(; default …)"."""
    cell = _cell(k)
    assert cell and not cell.startswith(","), cell
    if k.lo is not None:
        lo, hi = (int(k.lo), int(k.hi)) if k.kind == "int" else (f"{k.lo:g}", f"{k.hi:g}")
        assert f"{lo}–{hi}" in cell and (k.unit or "no unit") in cell, cell
    if k.kind == "list":
        assert cell.startswith("a list, each item") and "none twice" in cell, cell
    notes = [line for task in ("hdr", "hyperspectral", "depth") for line in template(task).splitlines()
             if line.startswith("# ")]
    if k.name not in ("preset", "sensor_distance_m"):
        assert any(line.startswith(f"# {k.help} ({cell}; default {k.default})") for line in notes), k.name
    assert not any("(;" in line for line in notes)


def test_a_key_under_its_earlier_name_is_refused_with_the_new_one(tmp_path):
    """``fabrication.levels`` (the level count) is now ``fabrication.n_levels``: one error says what to write."""
    from doefab.errors import DoefabError

    p = tmp_path / "s.toml"
    p.write_text('task = "hdr"\n[fabrication]\nlevels = 8\n')
    with pytest.raises(DoefabError, match=r"fabrication.levels is now fabrication.n_levels: write n_levels = 8"):
        load_scene(p)
    p.write_text('task = "hdr"\n[fabrication]\nlevels = 7\n')  # a value the new key refuses: named, not copied
    with pytest.raises(DoefabError, match=r"is now fabrication.n_levels, and fabrication.n_levels 7 is not one of "
                                          r"2, 4, 8, 16, 32"):
        load_scene(p)
    p.write_text('task = "hdr"\n[fabrication]\nlevels = 8\nn_levels = 16\n')  # both: the old one goes
    with pytest.raises(DoefabError, match=r"which this file sets too: delete levels"):
        load_scene(p)
    p.write_text('task = "hdr"\n[fabrication]\nn_levels = 8\n')
    assert load_scene(p).fabrication["n_levels"] == 8


def test_a_tolerance_stage_without_its_table_is_said_before_the_run(tmp_path):
    """``tolerance`` listed in the scene's stages but no ``[tolerance]`` table: the stage will be skipped, and doctor
    and run say so before any work (with the table to add); without the stage, or with the stages left at their
    default (all: a scene without ``[tolerance]`` is the way to run no Monte Carlo), nothing is said."""
    from doefab.pipeline.system import resolve

    text = template("hdr")
    cut = text[:text.index("[tolerance]")] + text[text.index("[holder]"):]  # the template without its table
    p = tmp_path / "s.toml"
    p.write_text(cut)
    said = [w for w in resolve(load_scene(p)).warnings if w.startswith("tolerance:")]
    assert len(said) == 1 and "will be skipped" in said[0] and "[tolerance]" in said[0]
    for text in (cut.replace('"tolerance", ', ""),  # not listed
                 "\n".join(ln for ln in cut.splitlines() if not ln.startswith("stages = "))):  # all by default
        p.write_text(text)
        assert not [w for w in resolve(load_scene(p)).warnings if w.startswith("tolerance:")]
