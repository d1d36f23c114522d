"""``doefab train``: writes to --out and says where, never replaces the shipped weights by accident, names a
design of another task at once."""

import hashlib
from pathlib import Path

import pytest

from doefab.errors import DoefabError

from cli_helpers import run_cli


def _digest(folder: Path, pattern: str) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.glob(pattern))}


def test_train_writes_to_out_and_prints_the_path(tmp_path, capsys, monkeypatch):
    import doefab.reconstruction.train as train_mod
    from doefab.reconstruction.weights import WEIGHTS_DIR

    shipped = WEIGHTS_DIR
    before = _digest(shipped, "hdr_uncoded_only*")
    real = train_mod.train
    monkeypatch.setattr(train_mod, "train", lambda *a, **k: real(*a, val_images=1,
                                                                 **{**k, "max_steps": 1, "conditions": None}))
    rc, out, _ = run_cli(["train", "--task", "hdr", "--variant", "uncoded_only", "--minutes", "0.1", "--crop", "64",
                       "--clean", "--out", tmp_path / "tr"], capsys)
    assert rc == 0
    assert _digest(shipped, "hdr_uncoded_only*") == before
    written = (tmp_path / "tr" / "hdr_uncoded_only.pt").resolve()
    assert written.is_file() and f"wrote {written} and its .json" in out


def test_the_shipped_folder_needs_the_explicit_flag(tmp_path, capsys):
    from doefab.reconstruction.weights import WEIGHTS_DIR, weights_target

    rc, _, err = run_cli(["train", "--task", "hdr", "--weights-dir", WEIGHTS_DIR, "--out", tmp_path / "tr"], capsys)
    assert rc == 2 and "--replace-shipped" in err and not (tmp_path / "tr").exists()
    assert weights_target(None, tmp_path, replace_shipped=True) == WEIGHTS_DIR
    with pytest.raises(DoefabError, match="committed design"):
        weights_target(None, tmp_path, replace_shipped=True, design=tmp_path)


def test_train_names_the_task_design_mismatch(tmp_path, capsys):
    rc, _, err = run_cli(["train", "--task", "hdr", "--design", "masks/grating", "--weights-dir", tmp_path / "w",
                       "--minutes", "0.1", "--out", tmp_path / "trw"], capsys)
    assert rc == 2
    assert "masks/grating is a hyperspectral (grating) design; --task hdr needs a streak design" in err
    assert list(tmp_path.iterdir()) == []
