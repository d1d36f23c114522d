"""Every subcommand against a catalogue of wrong inputs (issue: hardening).

Each case asserts: the expected non-zero exit status, exactly one line on stderr that names the problem,
no traceback, and nothing created, changed or deleted anywhere under the test's folder (inputs included).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from doefab.cli import main

REPO = Path(__file__).resolve().parents[2]


def _copy_design(fixtures, tmp, edit=None, levels=None):
    d = tmp / "design"
    shutil.copytree(fixtures / "design", d)
    if edit is not None:
        meta = json.loads((d / "design.json").read_text())
        edit(meta)
        (d / "design.json").write_text(json.dumps(meta))
    if levels is not None:
        np.save(d / "levels.npy", levels(np.load(d / "levels.npy")))
    return d


def _truncated_design(fixtures, tmp):
    d = _copy_design(fixtures, tmp)
    (d / "design.json").write_text((d / "design.json").read_text()[:100])
    return d


def _set(path, value):
    def edit(meta):
        obj = meta
        keys = path.split(".")
        for k in keys[:-1]:
            obj = obj[k]
        obj[keys[-1]] = value
    return edit


def _corrupt_gds(fixtures, tmp):
    m = tmp / "set"
    shutil.copytree(fixtures / "maskset", m)
    data = (m / "doe.gds").read_bytes()
    (m / "doe.gds").write_bytes(data[: len(data) // 3] + b"\x00garbage" * 50)
    return m


def _incomplete_set(fixtures, tmp):
    m = tmp / "set"
    shutil.copytree(fixtures / "maskset", m)
    (m / "README.txt").unlink()
    return m


def _garbled_manifest(fixtures, tmp):
    m = tmp / "set"
    shutil.copytree(fixtures / "maskset", m)
    (m / "manifest.json").write_text("{not json")
    return m


def _foreign(tmp):
    f = tmp / "mine"
    f.mkdir()
    (f / "thesis.tex").write_text("irreplaceable")
    return f


def _file(tmp):
    f = tmp / "afile"
    f.write_text("x")
    return f


def _text(tmp, name, text):
    (tmp / name).write_text(text)
    return tmp / name


def _npy(tmp, arr, name="h.npy"):
    np.save(tmp / name, arr)
    return tmp / name


# (id, argv builder (fixtures, tmp) -> list, expected status, substring the one line must contain)
CASES = [
    # ---- psf: flags
    ("psf-wavelength-in-metres", lambda f, t: ["psf", "--wavelengths-nm", "5.5e-7", "--out", str(t / "o")], 2,
     "5.5e-07 m is 550 nm: write 550"),
    ("psf-wavelength-in-micrometres", lambda f, t: ["psf", "--wavelengths-nm", "0.55", "--out", str(t / "o")], 2,
     "0.55 µm is 550 nm: write 550"),
    ("psf-negative-wavelength", lambda f, t: ["psf", "--wavelengths-nm", "-5", "--out", str(t / "o")], 2, "--wavelengths-nm"),
    ("psf-nan-wavelength", lambda f, t: ["psf", "--wavelengths-nm", "nan", "--out", str(t / "o")], 2, "--wavelengths-nm"),
    ("psf-wavelength-out-of-range", lambda f, t: ["psf", "--wavelengths-nm", "55", "--out", str(t / "o")], 2, "100–20000 nm"),
    ("psf-zero-depth", lambda f, t: ["psf", "--depths-m", "0", "--out", str(t / "o")], 2, "--depths-m"),
    ("psf-negative-depth", lambda f, t: ["psf", "--depths-m", "-2", "--out", str(t / "o")], 2, "depth > 0"),
    ("psf-zero-kernel", lambda f, t: ["psf", "--kernel", "0", "--out", str(t / "o")], 2, "--kernel"),
    ("psf-text-kernel", lambda f, t: ["psf", "--kernel", "big", "--out", str(t / "o")], 2, "expects an integer"),
    ("psf-bad-preset", lambda f, t: ["psf", "--preset", "imax", "--out", str(t / "o")], 2, "--preset"),
    ("psf-bad-route", lambda f, t: ["psf", "--route", "magic", "--out", str(t / "o")], 2, "--route"),
    ("psf-aliasing-window", lambda f, t: ["psf", "--kernel", "1001", "--out", str(t / "o")], 2, "--pupil-oversample"),
    # ---- psf: files
    ("psf-missing-height", lambda f, t: ["psf", "--height", str(t / "nope.npy"), "--out", str(t / "o")], 2, "not found"),
    ("psf-height-wrong-shape", lambda f, t: ["psf", "--height", str(_npy(t, np.zeros((10, 10)))), "--out", str(t / "o")],
     2, "--preset"),
    ("psf-height-not-npy", lambda f, t: ["psf", "--height", str(_file(t)), "--out", str(t / "o")], 2, "not a readable"),
    ("psf-height-nan", lambda f, t: ["psf", "--height", str(_npy(t, np.full((1600, 1600), np.nan))), "--out",
                                     str(t / "o")], 2, "NaN"),
    ("psf-height-in-nm", lambda f, t: ["psf", "--height", str(_npy(t, np.full((1600, 1600), 500.0))), "--out",
                                       str(t / "o")], 2, "500 nm is 5e-07 m"),
    ("psf-height-in-um", lambda f, t: ["psf", "--height", str(_npy(t, np.full((1600, 1600), 1.743))), "--out",
                                       str(t / "o")], 2, "1.743 µm is 1.743e-06 m"),
    ("psf-point-too-near", lambda f, t: ["psf", "--depths-m", "0.005", "--kernel", "31", "--out", str(t / "o")], 2,
     "--pupil-oversample"),
    ("psf-out-is-file", lambda f, t: ["psf", "--out", str(_file(t))], 2, "existing file"),
    ("psf-out-foreign-folder", lambda f, t: ["psf", "--out", str(_foreign(t)), "--force"], 2, "not a doefab psf output"),
    ("psf-out-under-a-file", lambda f, t: ["psf", "--out", str(_file(t) / "sub")], 2, "is a file"),
    # ---- design: flags
    ("design-negative-lr", lambda f, t: ["design", "--task", "streak", "--lr", "-1", "--out", str(t / "o")], 2, "--lr"),
    ("design-zero-lr", lambda f, t: ["design", "--task", "streak", "--lr", "0", "--out", str(t / "o")], 2, "> 0"),
    ("design-nan-lr", lambda f, t: ["design", "--task", "streak", "--lr", "nan", "--out", str(t / "o")], 2, "finite"),
    ("design-zero-sampling", lambda f, t: ["design", "--task", "streak", "--sampling", "0", "--out", str(t / "o")], 2,
     "--sampling"),
    ("design-sampling-not-divisor", lambda f, t: ["design", "--task", "grating", "--sampling", "3", "--out",
                                                  str(t / "o")], 2, "must divide"),
    ("design-zero-checkpoint", lambda f, t: ["design", "--task", "streak", "--checkpoint-every", "0", "--out",
                                             str(t / "o")], 2, "--checkpoint-every"),
    ("design-negative-seed", lambda f, t: ["design", "--task", "streak", "--seed", "-1", "--out", str(t / "o")], 2, "--seed"),
    ("design-zero-iterations", lambda f, t: ["design", "--task", "streak", "--iterations", "0", "--out", str(t / "o")],
     2, "--iterations"),
    ("design-qat-fraction", lambda f, t: ["design", "--task", "streak", "--qat-fraction", "2", "--out", str(t / "o")],
     2, "--qat-fraction"),
    ("design-batch", lambda f, t: ["design", "--task", "streak", "--batch", "-5", "--out", str(t / "o")], 2, "--batch"),
    ("design-knots-without-radial", lambda f, t: ["design", "--task", "streak", "--knots", "50", "--out",
                                                  str(t / "o")], 2, "--parameterization radial"),
    ("design-ring-law-wrong-task", lambda f, t: ["design", "--task", "streak", "--ring-law", "defocus", "--out",
                                                 str(t / "o")], 2, "half-ring"),
    ("design-bad-parameterization", lambda f, t: ["design", "--task", "streak", "--parameterization", "zernike",
                                                  "--out", str(t / "o")], 2, "--parameterization"),
    ("design-unknown-task", lambda f, t: ["design", "--task", "bokeh", "--out", str(t / "o")], 2, "--task"),
    ("design-resume-nothing", lambda f, t: ["design", "--task", "streak", "--resume", "--out", str(t / "o")], 2,
     "checkpoint"),
    ("design-resume-and-force", lambda f, t: ["design", "--task", "streak", "--resume", "--force", "--out",
                                              str(t / "o")], 2, "give one of them"),
    ("design-foreign-force", lambda f, t: ["design", "--task", "streak", "--force", "--out", str(_foreign(t))], 2,
     "never replaces"),
    # ---- masks: flags
    ("masks-name-traversal", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--name",
                                           "../evil"], 2, "not a plain file name"),
    ("masks-name-slash", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--name",
                                       "a/b"], 2, "--name"),
    ("masks-negative-cd", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--cd-um",
                                        "-1"], 2, "--cd-um"),
    ("masks-zero-cd", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--cd-um", "0"], 2,
     "--cd-um"),
    ("masks-zero-die", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--die-mm", "0"],
     2, "--die-mm"),
    ("masks-die-too-small", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--die-mm",
                                          "1.5"], 2, "--die-mm"),
    ("masks-vertex-cap", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--vertex-cap",
                                       "3"], 2, "--vertex-cap"),
    ("masks-etch-order", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(t / "o"), "--etch-order",
                                       "1", "1", "2", "3"], 2, "--etch-order"),
    ("masks-foreign-force", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(_foreign(t)),
                                          "--force"], 2, "never replaces"),
    ("masks-out-is-file", lambda f, t: ["masks", "--design", str(f / "design"), "--out", str(_file(t))], 2,
     "existing file"),
    # ---- masks: design.json read back
    ("masks-missing-design", lambda f, t: ["masks", "--design", str(t / "nothing"), "--out", str(t / "o")], 2,
     "design.json is missing"),
    ("masks-wavelength-in-nm", lambda f, t: ["masks", "--design", str(_copy_design(
        f, t, _set("camera.design_wavelength_m", 550))), "--out", str(t / "o")], 2, "design_wavelength_m"),
    ("masks-band-in-nm", lambda f, t: ["masks", "--design", str(_copy_design(f, t, _set("wavelengths_m", [550]))),
                                       "--out", str(t / "o")], 2, "wavelengths_m"),
    ("masks-level-count", lambda f, t: ["masks", "--design", str(_copy_design(f, t, _set("n_levels", 12))), "--out",
                                        str(t / "o")], 2, "n_levels = 12: a mask process makes L = 2, 4, 8, 16 or 32"),
    ("masks-level-count-edited", lambda f, t: ["masks", "--design", str(_copy_design(f, t, _set("n_levels", 8))),
                                               "--out", str(t / "o")], 2, "n_levels = 8"),
    ("masks-level-step", lambda f, t: ["masks", "--design", str(_copy_design(f, t, _set("level_step_m", 4e-8))),
                                       "--out", str(t / "o")], 2, "level_step_m"),
    ("masks-shape", lambda f, t: ["masks", "--design", str(_copy_design(f, t, _set("shape", [50, 50]))), "--out",
                                  str(t / "o")], 2, "shape"),
    ("masks-material", lambda f, t: ["masks", "--design", str(_copy_design(
        f, t, _set("camera.material.sellmeier_b", [1.0, 0.4, 0.9]))), "--out", str(t / "o")], 2, "Sellmeier"),
    ("masks-pitch", lambda f, t: ["masks", "--design", str(_copy_design(f, t, _set("camera.doe_pitch_m", 5.4))),
                                  "--out", str(t / "o")], 2, "doe_pitch_m"),
    ("masks-tampered-levels", lambda f, t: ["masks", "--design", str(_copy_design(
        f, t, levels=lambda lv: np.where(lv == 3, 4, lv).astype(np.uint8))), "--out", str(t / "o")], 2, "levels_sha256"),
    ("masks-truncated-json", lambda f, t: ["masks", "--design", str(_truncated_design(f, t)), "--out", str(t / "o")],
     2, "not valid JSON"),
    # ---- masks --verify
    ("verify-corrupt-gds", lambda f, t: ["masks", "--verify", str(_corrupt_gds(f, t)), "--no-klayout"], 3, "corrupt"),
    ("verify-corrupt-gds-klayout", lambda f, t: ["masks", "--verify", str(_corrupt_gds(f, t))], 3, "corrupt"),
    ("verify-incomplete", lambda f, t: ["masks", "--verify", str(_incomplete_set(f, t)), "--no-klayout"], 3, "incomplete"),
    ("verify-garbled-manifest", lambda f, t: ["masks", "--verify", str(_garbled_manifest(f, t))], 3, "not valid JSON"),
    ("verify-a-design-folder", lambda f, t: ["masks", "--verify", str(f / "design")], 2, "not a mask set"),
    ("verify-missing", lambda f, t: ["masks", "--verify", str(t / "nowhere")], 2, "not a folder"),
    ("verify-and-export", lambda f, t: ["masks", "--verify", str(f / "maskset"), "--out", str(t / "o")], 2, "one or the other"),
    # ---- holder
    ("holder-doe-too-far", lambda f, t: ["holder", "--out", str(t / "o"), "--no-step", "--no-renders", "--set",
                                         "lens_face_to_glass_mm=10"], 2, "doe_to_lens_mm"),
    ("holder-washer-recess", lambda f, t: ["holder", "--out", str(t / "o"), "--no-step", "--no-renders", "--set",
                                           "washer_recess_mm=30"], 2, "washer_recess_mm 30 is outside"),
    ("holder-thread-pitch", lambda f, t: ["holder", "--out", str(t / "o"), "--no-step", "--no-renders", "--set",
                                          "thread_pitch_mm=20"], 2, "thread_pitch_mm"),
    ("holder-unknown-param", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "colour=red"], 2, "unknown holder"),
    ("holder-nan", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "wall_mm=nan"], 2, "finite"),
    ("holder-text", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "clearance_mm=loose"], 2, "clearance_mm"),
    ("holder-negative", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "die_width_mm=-12"], 2, "die_width_mm"),
    ("holder-no-equals", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "wall_mm"], 2, "NAME=VALUE"),
    ("holder-clearance", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "clearance_mm=0.01"], 2, "clearance_mm 0.01 is outside 0.05–1 mm"),
    ("holder-segments", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "segments=100000"], 2, "segments"),
    ("holder-mount", lambda f, t: ["holder", "--out", str(t / "o"), "--set", "mount=magnet"], 2, "mount"),
    ("holder-out-is-file", lambda f, t: ["holder", "--out", str(_file(t))], 2, "existing file"),
    ("holder-foreign", lambda f, t: ["holder", "--out", str(_foreign(t)), "--force"], 2, "never replaces"),
    # ---- demo
    ("demo-zero-kernel", lambda f, t: ["demo", "--kernel", "0", "--out", str(t / "o")], 2, "--kernel"),
    ("demo-foreign", lambda f, t: ["demo", "--out", str(_foreign(t))], 2, "never replaces"),
    # ---- train / evaluate
    ("train-zero-minutes", lambda f, t: ["train", "--task", "hdr", "--minutes", "0", "--out", str(t / "o")], 2,
     "--minutes"),
    ("train-crop", lambda f, t: ["train", "--task", "hdr", "--crop", "100", "--out", str(t / "o")], 2, "multiple of 32"),
    ("train-resume-nothing", lambda f, t: ["train", "--task", "hdr", "--resume", "--out", str(t / "o")], 2,
     "checkpoint"),
    ("train-foreign", lambda f, t: ["train", "--task", "hdr", "--force", "--out", str(_foreign(t))], 2,
     "never replaces"),
    ("evaluate-missing-weights", lambda f, t: ["evaluate", "--task", "hdr", "--weights-dir", str(t / "none"),
                                               "--out", str(t / "o")], 2, "doefab train --task hdr"),
    ("evaluate-design-without-weights-dir", lambda f, t: ["evaluate", "--task", "hyperspectral", "--design",
                                                          str(f / "design"), "--out", str(t / "o")], 2,
     "--weights-dir"),
    ("train-design-of-another-task", lambda f, t: ["train", "--task", "depth", "--design", str(f / "design"),
                                                   "--out", str(t / "o")], 2, "needs a half-ring design"),
    ("train-missing-design", lambda f, t: ["train", "--task", "depth", "--design", str(t / "none"), "--weights-dir",
                                           str(t / "w"), "--out", str(t / "o")], 2, "design.json is missing"),
    ("evaluate-bad-variant", lambda f, t: ["evaluate", "--task", "depth", "--variants", "best", "--out",
                                           str(t / "o")], 2, "--variants"),
    ("finetune-missing-design", lambda f, t: ["finetune", "--design", str(t / "none"), "--out", str(t / "o")], 2,
     "design.json is missing"),
    ("finetune-zero-minutes", lambda f, t: ["finetune", "--design", str(f / "design"), "--minutes", "0", "--out",
                                            str(t / "o")], 2, "--minutes"),
    ("finetune-not-depth", lambda f, t: ["finetune", "--design", str(f / "design"), "--minutes", "1", "--out",
                                         str(t / "o")], 2, "half-ring"),
    ("evaluate-size", lambda f, t: ["evaluate", "--task", "depth", "--size", "100", "--out", str(t / "o")], 2,
     "multiple of 32"),
    # ---- run / doctor / tolerance
    ("run-missing-scene", lambda f, t: ["run", str(t / "nope.toml"), "--out", str(t / "o")], 2, "not found"),
    ("run-bad-scene", lambda f, t: ["run", str(_text(t, "s.toml", 'task = "hdr"\n[optics]\ndepths_m = [-1]\n'
                                                     'kernel_px = 4\n')), "--out", str(t / "o")], 2, "2 problems:"),
    ("run-not-toml", lambda f, t: ["run", str(_text(t, "s.toml", "task = ")), "--out", str(t / "o")], 2,
     "not valid TOML"),
    ("run-bad-force", lambda f, t: ["run", str(REPO / "scenes" / "hdr.toml"), "--force", "paint", "--out", str(t / "o")], 2, "paint"),
    ("doctor-missing", lambda f, t: ["doctor", str(t / "nope.toml")], 2, "not found"),
    ("tolerance-missing-design", lambda f, t: ["tolerance", "--design", str(t / "none"), "--out", str(t / "o")], 2,
     "design.json is missing"),
    ("tolerance-bad-budget", lambda f, t: ["tolerance", "--design", str(f / "design"), "--budget",
                                           str(_text(t, "b.toml", "[overlay]\nshift_sigma_um = 99\n")),
                                           "--out", str(t / "o")], 2, "overlay.shift_sigma_um = 99"),
    ("tolerance-missing-holder", lambda f, t: ["tolerance", "--design", str(f / "design"), "--holder",
                                               str(t / "nope"), "--out", str(t / "o")], 2, "no holder.json"),
    ("tolerance-not-a-holder", lambda f, t: ["tolerance", "--design", str(f / "design"), "--holder",
                                             str(_text(t, "holder.json", "{}")), "--out", str(t / "o")], 2,
     "not a doefab holder.json"),
    ("tolerance-bad-scheduler", lambda f, t: ["tolerance", "--design", str(f / "design"), "--scheduler", "mars",
                                              "--out", str(t / "o")], 2, "--scheduler"),
    # ---- usage
    ("unknown-flag", lambda f, t: ["psf", "--colour", "red", "--out", str(t / "o")], 2, "unrecognized"),
    ("missing-out", lambda f, t: ["psf"], 2, "--out"),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_wrong_input_gives_one_clear_line(case, one_clear_error):
    name, build, status, needle = case
    one_clear_error(build, status, needle)


def test_catalogue_is_large_enough():
    assert len(CASES) >= 40
    assert {c[1](None, None)[0] if False else c[0].split("-")[0] for c in CASES} >= {"psf", "design", "masks",
                                                                                     "verify", "holder", "demo"}


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_output_parent_is_refused_before_work(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert main(["psf", "--out", str(ro / "o")]) == 2
        assert "cannot write" in capsys.readouterr().err
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)
