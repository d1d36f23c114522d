"""``doefab masks --verify`` re-derives every depth of a mask set's manifest and README."""

import json
import shutil
from pathlib import Path

import doefab

from cli_helpers import REPO, run_cli


def _half_ring_copy(tmp: Path) -> Path:
    dst = tmp / "COPY"
    shutil.copytree(REPO / "masks" / "half-ring", dst)
    return dst


def _edit_manifest(folder: Path, edit) -> None:
    man = json.loads((folder / "manifest.json").read_text())
    edit(man)
    (folder / "manifest.json").write_text(json.dumps(man, indent=2))


def test_verify_names_every_inconsistent_depth_field(tmp_path, capsys):
    copy = _half_ring_copy(tmp_path)

    def edit(man):
        assert man["layers"][4]["etch_depth_nm"] == 597.942
        man["layers"][4]["etch_depth_nm"] = 1000
        man["level_step_nm"] *= 1.1

    _edit_manifest(copy, edit)
    rc, out, err = run_cli(["masks", "--verify", copy], capsys)
    assert rc == 3 and "verified" not in out
    assert "layers[4].etch_depth_nm = 1000 (expected 597.942" in err and "level_step_nm = 82.2" in err


def test_a_consistently_edited_wavelength_differs_from_the_design(tmp_path, capsys):
    from doefab.fabrication.manifest import depth_fields

    copy = _half_ring_copy(tmp_path)

    def edit(man):  # every depth re-derived for 600 nm: self-consistent, but not the design's wavelength
        f = depth_fields(doefab.FUSED_SILICA, 600e-9)
        man.update(design_wavelength_m=600e-9, level_step_nm=f["level_step_nm"],
                   level_to_height_nm=f["level_to_height_nm"],
                   refractive_index_at_design_wavelength=f["refractive_index_at_design_wavelength"])
        for layer in man["layers"]:
            if layer["purpose"] == "etch":
                layer["etch_depth_nm"] = f["etch_depth_nm"][layer["bit"]]

    _edit_manifest(copy, edit)
    rc, _, err = run_cli(["masks", "--verify", copy, "--no-klayout"], capsys)
    assert rc == 3 and "differs from the design's 5.5e-07" in err


def test_a_hand_edited_readme_fails(tmp_path, capsys):
    copy = _half_ring_copy(tmp_path)
    text = (copy / "README.txt").read_text()
    (copy / "README.txt").write_text(text.replace("etch depth 597.942 nm", "etch depth 1000 nm"))
    rc, _, err = run_cli(["masks", "--verify", copy, "--no-klayout"], capsys)
    assert rc == 3 and "README.txt differs" in err
