"""The committed designs shipped in the package equal the repository's mask sets' designs, and unpack to a
design folder from an empty cache."""

import json
from pathlib import Path

import numpy as np
import pytest

from doefab.design.committed import COMMITTED, committed_dir
from doefab.design.packing import pack_design
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


@pytest.mark.parametrize("damage", ["flip a level", "truncate", "edit design.json"])
def test_a_damaged_cached_design_is_rebuilt_from_the_package(cache, damage):
    """A cached copy that no longer equals the package's (a flipped byte, a cut file, an edited record) is written
    afresh on the next use, so the design loads instead of failing on its checksum."""
    folder = committed_dir("grating")
    ref = Design.load(REPO / "masks" / "grating" / "design")
    lv = folder / "levels.npy"
    if damage == "flip a level":
        arr = np.load(lv)
        arr[0, 0] = (int(arr[0, 0]) + 1) % 16
        np.save(lv, arr)
    elif damage == "truncate":
        lv.write_bytes(lv.read_bytes()[:1000])
    else:
        meta = json.loads((folder / "design.json").read_text())
        meta["seed"] = 12345
        (folder / "design.json").write_text(json.dumps(meta))
    with pytest.raises(DoefabError) if damage != "edit design.json" else _no_error():
        Design.load(folder)  # the damage is real: the folder as left does not load (or loads another record)
    again = committed_dir("grating")
    assert again == folder
    d = Design.load(again)
    np.testing.assert_array_equal(d.levels, ref.levels)
    assert d.seed == ref.seed


class _no_error:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
