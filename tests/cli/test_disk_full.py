"""A full disk names the file that could not be written, by its whole path, and says the fix."""

import errno
import os

from doefab.cli import main


def test_a_full_disk_names_the_whole_path_and_the_fix(tmp_path, monkeypatch, capsys):
    out = tmp_path / "deep" / "psf"
    real_fsync = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    try:
        status = main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)])
    finally:
        monkeypatch.setattr(os, "fsync", real_fsync)
    err = capsys.readouterr().err
    assert status == 2, err
    assert f"cannot read or write {out}" in err and "No space left on device" in err, err
    assert "free space on that disk" in err
    assert err.count("\n") == 1  # one line


def test_a_full_disk_in_a_writer_that_names_no_file_names_the_output_folder(tmp_path, monkeypatch, capsys):
    """A stream or figure writer whose error carries no file name (as writing to a full disk gives): the message
    names the output folder by its whole path, and the fix."""
    import doefab.cli.psf as psf_cli

    out = tmp_path / "deep" / "psf"

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")  # no filename, as fh.write gives

    monkeypatch.setattr(psf_cli, "run", lambda args: (setattr(args, "out", str(out)), full())[1])
    status = main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2 and f"a file under {out}" in err and "free space on that disk" in err, err


def test_a_cache_that_cannot_be_written_is_told_to_move_by_doefab_cache(tmp_path, monkeypatch, capsys):
    """A read-only home (the cache under ~/.cache): the one-line error names the cache and $DOEFAB_CACHE; an
    unwritable file elsewhere gets no such hint."""
    import doefab.cli.psf as psf_cli

    cache = tmp_path / "home" / ".cache" / "doefab"
    monkeypatch.delenv("DOEFAB_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache.parent))
    for where, hinted in ((cache.parent, True), (cache / "designs" / "x", True), (tmp_path / "mine", False)):
        denied = OSError(errno.EACCES, "Permission denied")
        denied.filename = str(where)
        monkeypatch.setattr(psf_cli, "run", lambda args, e=denied: (_ for _ in ()).throw(e))
        status = main(["psf", "--wavelengths-nm", "550", "--kernel", "31", "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert status == 2 and ("set $DOEFAB_CACHE to a folder you can write" in err) == hinted, err
        assert err.count("\n") == 1
