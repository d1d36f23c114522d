"""The committed designs shipped in the package equal the repository's mask sets' designs, and unpack to a
design folder from an empty cache."""

import json
from pathlib import Path

import numpy as np
import pytest

from doefab.design.committed import COMMITTED, committed_dir, pack_design
from doefab.design.design import Design
from doefab.errors import DoefabError

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DOEFAB_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.mark.parametrize("name", COMMITTED)
def test_packaged_design_equals_the_mask_set_design(name, cache):
    folder = committed_dir(name)
    assert folder.is_relative_to(cache)
    ref = REPO / "masks" / name / "design"
    np.testing.assert_array_equal(np.load(folder / "levels.npy"), np.load(ref / "levels.npy"))
    assert json.loads((folder / "design.json").read_text()) == json.loads((ref / "design.json").read_text())
    assert Design.load(folder).levels.shape == Design.load(ref).levels.shape


def test_pack_and_unknown_name(tmp_path, cache):
    out = pack_design(REPO / "masks" / "grating" / "design", "grating", tmp_path / "g.npz")
    with np.load(out) as z:
        np.testing.assert_array_equal(z["levels"], np.load(REPO / "masks/grating/design/levels.npy"))
    with pytest.raises(DoefabError, match="ships streak"):
        committed_dir("spiral")
