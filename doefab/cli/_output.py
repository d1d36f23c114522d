"""Claiming a command's output folder before any work starts (see ``doefab.io.OutputDir``)."""

from __future__ import annotations

from pathlib import Path

from doefab.io import OutputDir


def check_resume(out: OutputDir) -> None:
    """``--resume``: the earlier run's checkpoint must be there and readable, before any work."""
    from doefab.design.checkpoint import read_checkpoint
    from doefab.errors import DoefabError

    ckpt = out.path / "checkpoint.pt"
    if not ckpt.is_file():
        raise DoefabError(f"--resume: {ckpt} does not exist, so there is nothing to continue: start afresh with "
                          f"--force instead of --resume")
    read_checkpoint(ckpt)


def resume_hint(kept: str, force: bool) -> str:
    """What an interrupted run prints: ``kept`` (what stays) and how to continue, which for a ``--force`` run is
    the command with ``--resume`` in its place (repeated as it was, ``--force`` would start afresh again)."""
    how = "with --resume in place of --force" if force else "with --resume"
    return f"{kept}: rerun the same command {how} to continue"


def checkpoint_hint(path, kept: str, force: bool):
    """``resume_hint`` for a run whose loop clears an earlier run's checkpoint only where it starts (after its own
    checks and set-up): a ``--force`` run interrupted before that finds the earlier run's checkpoint in ``path``
    untouched, and the hint then says so — rerun as given to start afresh, or with ``--resume`` in place of
    ``--force`` to continue that earlier run — where ``--resume`` would otherwise continue the earlier run unawares.
    A callable the CLI calls at the interrupt (a plain ``resume_hint`` without ``--force``)."""
    if not force:
        return resume_hint(kept, False)
    ckpt = Path(path) / "checkpoint.pt"
    before = _stamp(ckpt)

    def hint() -> str:
        if before is not None and _stamp(ckpt) == before:
            return (f"the earlier run's checkpoint in {path} is kept, untouched (this run stopped before its first "
                    f"step): rerun the same command to start afresh, or with --resume in place of --force to "
                    f"continue the earlier run")
        return resume_hint(kept, True)

    return hint


def _stamp(path):
    """(inode, modification time, size) of a file, None where there is none."""
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def clear_earlier_run(out: OutputDir, force: bool, extra=()) -> None:
    """``--force``: remove the earlier run's checkpoint (and a checkpoint write a kill left half done), its history
    and ``extra`` files from the run folder before any work, so neither a later ``--resume`` nor a reader mixes the
    two runs (the folder is doefab's: ``claim_output`` checked its marker)."""
    if not force or not out.path.is_dir():
        return
    from doefab.design.checkpoint import clear_checkpoint

    clear_checkpoint(out.path)
    for f in extra:
        if f.is_file():
            f.unlink()


def claim_output(args, kind: str, replace: bool, keep_on_failure=None, replace_flag: str = "--force") -> OutputDir:
    """Validate ``args.out`` for a ``kind`` output and register it so a failed run removes what it created."""
    out = OutputDir(args.out, kind, replace=replace, replace_flag=replace_flag)
    args.outdir = out
    args.keep_on_failure = keep_on_failure
    return out
