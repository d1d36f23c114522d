"""``doefab diagnose`` end to end on a measured pair: the three files (diagnosis.json, psf_pair_fitted.npz,
diagnosis.html); a pair of another design, or one whose design is not named, refused with one line (exit 2)
and nothing written."""

import json

import numpy as np
import pytest
import torch

import doefab


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A streak design quantized from the task's starting relief on a 48-pixel DOE at 2.7 µm (two bands, kernel
    31 px, the right half plain), a budget whose decenter suits its 0.13 mm aperture, and the pair (one band) of a
    part whose mask 2 is 1 µm off, computed on a grid twice finer."""
    from doefab.design.design import Design
    from doefab.fabrication.levels import levels_sha256
    from doefab.tasks import get_task
    from doefab.tolerance.errors import PartErrors
    from doefab.tolerance.judge import PSFJudge

    cam = doefab.Camera(aperture_diameter=48 * 2.7e-6, doe_pitch=2.7e-6, doe_pixels=48, sensor_pitch=5.4e-6,
                        sensor_distance=20e-3, focus_distance=5.0)
    task = get_task("streak", kernel_size=31, arm_px=10)
    task.bind(cam)
    lv = doefab.quantize_levels(task.init_height(cam, np.random.default_rng(2)), cam)
    lv[:, 24:] = 15
    d = Design(task="streak", task_params=task.params(), camera=cam, wavelengths=(656e-9, 589e-9), depths=(5.0,),
               height=doefab.levels_to_height(lv, cam), levels=lv, metrics={"name": "m", "continuous": 0.5,
                                                                            "quantized": 0.5})
    root = tmp_path_factory.mktemp("diag")
    d.save(root / "design")
    (root / "budget.toml").write_text("[mounting]\ndecenter_max_mm = 0.004\n")
    part = PartErrors(overlay=((0.0, 0.0), (1e-6, 0.0), (0.0, 0.0), (0.0, 0.0)))
    with torch.no_grad():
        got = PSFJudge(d, 2).psfs(part, halves=("coded", "uncoded"))
    pair = doefab.PSFPair(got["coded"][:, 1:], got["uncoded"][:, 1:], d.wavelengths[1:], d.depths,
                          cam.sensor_pitch)  # the lab recorded one of the two bands
    pair.save(root / "psf_pair.npz", {"source": "simulation", "levels_sha256": levels_sha256(lv),
                                      "design": str(root / "design")})
    pair.save(root / "other.npz", {"source": "simulation", "levels_sha256": "f" * 64})
    pair.save(root / "unnamed.npz", {"source": "simulation"})
    return root


def test_diagnose_writes_the_three_files(measured, tmp_path, capsys, monkeypatch):
    """The design comes from the pair's provenance; the fitted pair holds every band of the design though the lab
    recorded one; a second run into the same folder needs --force and is refused before any work. (The fit is cut
    short: its quality is tests/lab/test_lab_diagnose.py's business.)"""
    from doefab.cli import main
    from doefab.lab import diagnose, uncertainty

    for name, value in (("MAX_STEPS", 3), ("REWEIGHT", 1)):
        monkeypatch.setattr(diagnose, name, value)
    monkeypatch.setattr(uncertainty, "REFINE", 1)

    out = tmp_path / "diag"
    argv = ["diagnose", "--psf", str(measured / "psf_pair.npz"), "--budget", str(measured / "budget.toml"),
            "--starts", "1", "--out", str(out)]
    assert main(argv) == 0
    assert {p.name for p in out.iterdir()} >= {"diagnosis.json", "psf_pair_fitted.npz", "diagnosis.html"}
    said = capsys.readouterr().out
    diag = json.loads((out / "diagnosis.json").read_text())
    assert diag["measured"]["wavelengths_nm"] == pytest.approx([589.0])
    assert all(a in said for a in diag["actions"])
    fitted = doefab.PSFPair.load(out / "psf_pair_fitted.npz")
    assert fitted.coded.shape == (1, 2, 31, 31) and fitted.provenance["source"] == "diagnose"
    assert fitted.provenance["levels_sha256"] == diag["design_levels_sha256"]
    page = (out / "diagnosis.html").read_text()
    assert "What to do" in page and "data:image/png;base64," in page
    assert page.index("What the part delivers") < page.index("<table>")  # words first
    assert main(argv) == 2


def test_a_pair_of_another_design_is_refused(measured, one_clear_error):
    one_clear_error(lambda fx, work: ["diagnose", "--psf", measured / "other.npz", "--design", measured / "design",
                                      "--out", "diag"], 2, "levels_sha256 ffffffffffffffff")


def test_a_pair_that_names_no_design_needs_one(measured, one_clear_error):
    one_clear_error(lambda fx, work: ["diagnose", "--psf", measured / "unnamed.npz", "--out", "diag"], 2,
                    "--design is needed")


def test_the_starts_default_is_the_diagnosis_default(monkeypatch, measured, tmp_path):
    """Without --starts the CLI leaves the count to ``diagnose`` (its ``STARTS``), and its help names that count;
    with it, the count reaches ``diagnose``."""
    import argparse

    import doefab.lab.diagnose as dg
    from doefab.cli import diagnose as cli

    sub = argparse.ArgumentParser().add_subparsers()
    cli.register(sub)
    assert f"default {dg.STARTS}:" in sub.choices["diagnose"].format_help().replace("\n", " ").replace("  ", " ")
    seen = {}

    def fake(pair, folder, budget, **kw):
        seen.update(kw)
        raise SystemExit(0)
    monkeypatch.setattr(dg, "diagnose", fake)
    with pytest.raises(SystemExit):
        doefab.cli.main(["diagnose", "--psf", str(measured / "psf_pair.npz"), "--out", str(tmp_path / "o")])
    assert "starts" not in seen and "seed" in seen
    with pytest.raises(SystemExit):
        doefab.cli.main(["diagnose", "--psf", str(measured / "psf_pair.npz"), "--starts", "3", "--out",
                         str(tmp_path / "o2")])
    assert seen["starts"] == 3
