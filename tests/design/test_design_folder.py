"""Where a design folder is (a mask set's ``design/``) and the PSF window its task uses."""

import json
import shutil
from pathlib import Path

from doefab.design.design import Design, design_folder_of

REPO = Path(__file__).resolve().parents[2]


def test_a_mask_set_names_its_design_folder_and_anything_else_itself(tmp_path):
    streak = REPO / "masks" / "streak"
    assert design_folder_of(streak) == streak / "design"
    assert design_folder_of(streak / "design") == streak / "design"
    assert design_folder_of(str(tmp_path)) == tmp_path


def test_kernel_size_is_the_stored_one_else_the_task_default(tmp_path):
    from doefab.tasks.streak import StreakTask

    d = tmp_path / "design"
    shutil.copytree(REPO / "masks" / "streak" / "design", d)
    record = json.loads((d / "design.json").read_text())
    record["task_params"]["kernel_size"] = 127
    (d / "design.json").write_text(json.dumps(record))
    assert Design.load(d).kernel_size == 127
    del record["task_params"]["kernel_size"]
    (d / "design.json").write_text(json.dumps(record))
    assert Design.load(d).kernel_size == StreakTask.__dataclass_fields__["kernel_size"].default != 127


def test_a_shipped_designs_name_reaches_it_where_no_masks_folder_is(tmp_path, monkeypatch, capsys):
    """An installed package has no ``masks/``: ``streak``, ``masks/streak`` and ``masks/half-ring/design`` (the
    names the README and the help use) reach the committed designs, with the levels of the repository's mask sets;
    a folder of the user's by that name is the user's, and is read as such."""
    import numpy as np
    import pytest

    from doefab.cli import main
    from doefab.cli._args import design_folder
    from doefab.errors import DoefabError

    monkeypatch.setenv("DOEFAB_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    for name, given in (("streak", "streak"), ("grating", "masks/grating"), ("half-ring", "masks/half-ring/design")):
        folder, design = design_folder(given)
        assert design.task == name and (tmp_path / "cache") in folder.parents
        shipped = np.load(REPO / "masks" / name / "design" / "levels.npy")
        assert np.array_equal(np.load(folder / "levels.npy"), shipped)
    assert design_folder_of("elsewhere/streak") == Path("elsewhere/streak")  # not a masks/ path: itself
    (tmp_path / "streak").mkdir()
    with pytest.raises(DoefabError, match="design.json is missing"):
        design_folder("streak")
    # the command line too: the design is read (its layers named) before the output is claimed, and the fallback
    # is said, not silent (a folder of that name may be what was meant)
    assert main(["masks", "--design", "masks/half-ring", "--out", str(tmp_path / "m"), "--etch-order", "9"]) == 2
    err = capsys.readouterr().err
    assert "this 16-level design" in err and "using the shipped design 'half-ring'" in err
    # train/evaluate: the committed design by its name is the shipped networks' own, not "another design"
    from argparse import Namespace

    from doefab.cli._args import task_design_arg

    args = Namespace(task="hdr", design="masks/streak", weights_dir=None)
    assert task_design_arg(args, need_weights_dir=True) is None
