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
