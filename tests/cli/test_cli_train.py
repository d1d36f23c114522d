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


def test_force_over_an_earlier_run_starts_afresh_and_resume_without_a_checkpoint_names_force(tmp_path, capsys,
                                                                                              monkeypatch):
    """``--force`` removes the earlier run's checkpoint, history, weights and a half-written checkpoint before it
    trains (an interrupted new run must not resume or publish the old one); ``--resume`` with no checkpoint names
    ``--force``, the flag that works there."""
    import doefab.reconstruction.train as train_mod

    argv = ["train", "--task", "hdr", "--variant", "uncoded_only", "--minutes", "0.1", "--crop", "64", "--clean",
            "--out", tmp_path / "tr"]
    real = train_mod.train
    monkeypatch.setattr(train_mod, "train", lambda *a, **k: real(*a, val_images=1,
                                                                 **{**k, "max_steps": 1, "conditions": None}))
    assert run_cli(argv, capsys)[0] == 0
    run = tmp_path / "tr"
    old = {p.name for p in run.iterdir()}
    assert {"checkpoint.pt", "history.csv", "hdr_uncoded_only.pt", "hdr_uncoded_only.json"} <= old
    (run / ".checkpoint.pt.x1y2").write_bytes(b"half")

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_mod, "train", interrupted)
    rc, _, err = run_cli(argv + ["--force"], capsys)
    assert rc == 130
    left = {p.name for p in run.iterdir()}
    assert not left & {"checkpoint.pt", "history.csv", "hdr_uncoded_only.pt", "hdr_uncoded_only.json",
                       ".checkpoint.pt.x1y2"}, left
    rc, _, err = run_cli(argv + ["--resume"], capsys)
    assert rc == 2 and "start afresh with --force instead of --resume" in err


def test_a_weights_folder_that_cannot_be_made_is_refused_before_training(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    rc, _, err = run_cli(["train", "--task", "hdr", "--weights-dir", tmp_path / "notes.txt" / "w", "--minutes", "0.1",
                          "--out", tmp_path / "tr"], capsys)
    assert rc == 2 and "notes.txt is a file, so the folder cannot be made" in err
    assert not (tmp_path / "tr").exists() and (tmp_path / "notes.txt").read_text() == "mine"


def test_running_out_of_memory_in_training_names_the_batch_and_crop(tmp_path, capsys, monkeypatch):
    """torch's allocator raises a RuntimeError ("can't allocate memory"): one line naming what to lower, not an
    internal error."""
    import doefab.reconstruction.train as train_mod

    def oom(*a, **k):
        raise RuntimeError("[enforce fail at alloc_cpu.cpp:117] DefaultCPUAllocator: can't allocate memory: you tried "
                           "to allocate 123456789 bytes")

    monkeypatch.setattr(train_mod, "train", oom)
    rc, _, err = run_cli(["train", "--task", "hdr", "--minutes", "0.1", "--clean", "--out", tmp_path / "tr"], capsys)
    assert rc == 2 and "out of memory: lower --batch or --crop" in err and "internal error" not in err

