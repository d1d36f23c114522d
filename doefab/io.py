"""Files and folders the commands write: atomic, umask-respecting, and never someone else's folder.

- ``atomic_write_bytes`` (and text/json): temporary file beside the target, fsync, atomic rename; the file
  gets the permissions the user's umask gives any new file (``mkstemp`` alone would leave 0600).
- ``staging_dir``: a folder built beside its target and swapped in only when complete; stale staging folders
  of killed runs (their process is gone) are removed first.
- ``OutputDir``: the output folder of one command run. It refuses, before any work starts, a path that is
  a file, a folder that cannot be written, and a non-empty folder that is not this command's own kind of
  output, even with ``--force``; on failure it removes what the run created.
- Ownership: only the marker file ``.doefab-output.json`` (written by ``mark_folder``) proves that a folder
  is doefab's; file names inside a folder never do (a user's ``run.json`` or ``summary.json`` is theirs).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import tempfile
from pathlib import Path

from doefab.errors import DoefabError

__all__ = ["cache_root", "atomic_write_bytes", "atomic_write_text", "atomic_write_json", "json_text", "json_ready",
           "read_json", "from_json_ready", "staging_dir", "OutputDir", "folder_lock", "sources_sha256", "MARKER", "plain_name", "apply_umask", "read_marker",
           "mark_folder", "owned_by_doefab", "read_toml"]

MARKER = ".doefab-output.json"


def _umask() -> int:
    """The process umask (read by setting and restoring it; read every time, as the user may change it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def apply_umask(path: str | Path) -> None:
    """Give ``path`` the mode a plain ``open``/``mkdir`` would (0666/0777 less the umask)."""
    path = Path(path)
    base = 0o777 if path.is_dir() else 0o666
    os.chmod(path, base & ~_umask())


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` via a temporary file in the same folder and an atomic rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno is not None:  # a full disk names no file: name the target
            raise OSError(exc.errno, exc.strerror or str(exc), str(path.absolute())) from exc
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def json_text(obj, indent: int = 2) -> str:
    """``obj`` as strict JSON text (``json_ready``: a non-finite number as "inf", "-inf" or "nan"), which a
    browser's ``JSON.parse`` and jq read; ``read_json`` gives the numbers back.

    Example: ``json_text({"margin": float("inf")}, indent=None)`` → ``'{"margin": "inf"}'``."""
    return json.dumps(json_ready(obj), indent=indent, allow_nan=False)


def atomic_write_json(path: str | Path, obj) -> Path:
    """Write ``obj`` as strict JSON (``json_text``)."""
    return atomic_write_text(path, json_text(obj) + "\n")


def read_json(path: str | Path):
    """A JSON file doefab wrote (``atomic_write_json``), each "inf", "-inf" or "nan" string a float again; raises
    OSError or ValueError as ``json.loads`` does.

    Example: a file holding ``{"margin": "inf"}`` → ``{"margin": inf}``."""
    return from_json_ready(json.loads(Path(path).read_text()))


_NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def from_json_ready(obj):
    """``json_ready``'s inverse: each "inf", "-inf" or "nan" string a float.

    Example: ``from_json_ready({"rows": [1.0, "nan"]})`` → ``{"rows": [1.0, nan]}``."""
    if isinstance(obj, str):
        return _NON_FINITE.get(obj, obj)
    if isinstance(obj, dict):
        return {k: from_json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [from_json_ready(v) for v in obj]
    return obj


def json_ready(obj):
    """``obj`` with each non-finite float written as the scene files write it ("inf", "-inf", "nan"): strict JSON
    readers (a browser's ``JSON.parse``, jq) refuse the ``Infinity`` and ``NaN`` that Python's json writes.

    Example: ``json_ready({"margin": float("inf"), "rows": [1.0, float("nan")]})`` →
    ``{"margin": "inf", "rows": [1.0, "nan"]}``."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if obj != obj else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    return obj


_PLAIN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def plain_name(name: str, what: str = "--name") -> str:
    """Return ``name`` if it is a plain file name (letters, digits, ``_ . -``; no path, no leading dot)."""
    if not isinstance(name, str) or not _PLAIN.match(name) or ".." in name:
        raise DoefabError(f"{what} {name!r} is not a plain file name: use letters, digits, '_', '-' and '.' only "
                          f"(no '/', no '..', not starting with '.'), e.g. {what} streak")
    return name


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


_STALE = re.compile(r"\.(staging|old)\.(\d+)\.")


def clean_stale_staging(final: Path) -> list[Path]:
    """Remove staging/old folders beside ``final`` left by runs whose process no longer exists."""
    removed = []
    parent = final.parent
    if not parent.is_dir():
        return removed
    for p in parent.glob(f".{final.name}.*"):
        m = _STALE.match(p.name[len(final.name) + 1:])
        if not p.is_dir() or m is None:
            continue
        if not _pid_alive(int(m.group(2))) or int(m.group(2)) == os.getpid():
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


@contextlib.contextmanager
def staging_dir(final: str | Path):
    """Yield a temporary folder beside ``final``; on success it replaces ``final`` (two renames).

    On any exception the staging folder is removed and ``final`` is left as it was. Staging folders of
    killed runs are removed before a new one is made.
    """
    final = Path(final)
    made = None  # the outermost parent folder this call creates (removed again on failure)
    q = final.absolute().parent
    while not q.exists():
        made, q = q, q.parent
    final.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_staging(final)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.staging.{os.getpid()}.", dir=final.parent))
    apply_umask(tmp)
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if made is not None:
            shutil.rmtree(made, ignore_errors=True)
        raise
    old = None
    if final.exists():
        old = final.parent / f".{final.name}.old.{os.getpid()}.x"
        os.replace(final, old)
    os.replace(tmp, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _nearest_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists():
        p = p.parent
    return p


@contextlib.contextmanager
def folder_lock(folder: str | Path, what: str = "doefab run"):
    """Hold an exclusive lock on ``folder`` (its file ``.doefab-lock``, locked with ``flock``) while the block
    runs; a second holder is refused at once with one error naming the process that holds it. The lock ends with
    the process, however it ends (a killed run leaves no stale lock)."""
    import fcntl
    import time

    path = Path(folder) / ".doefab-lock"
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "another process"
            raise DoefabError(f"{folder} is in use by {holder}: two runs must not write one output folder; wait "
                              f"for that run to finish (it releases the folder when it ends), or choose another "
                              f"--out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{what} (process {os.getpid()}, since {time.strftime('%Y-%m-%d %H:%M:%S')})".encode(), 0)
        yield path
    finally:
        os.close(fd)  # closing the descriptor releases the lock


def read_marker(folder: Path) -> dict | None:
    """The ownership marker of ``folder`` (a dict with ``kind``), or None when it has none (or a broken one)."""
    try:
        d = json.loads((Path(folder) / MARKER).read_text())
        return d if isinstance(d, dict) and d.get("written_by") == "doefab" else None
    except (OSError, ValueError):
        return None


def mark_folder(folder: str | Path, kind: str, **extra) -> None:
    """Write the ownership marker: ``folder`` is doefab's output of ``kind`` (``extra``: more fields)."""
    atomic_write_json(Path(folder) / MARKER, {"kind": kind, "written_by": "doefab", **extra})


def owned_by_doefab(folder: str | Path, kind: str, **fields) -> bool:
    """True when ``folder`` is empty or missing, or carries a marker of ``kind`` whose ``fields`` match: the
    only condition under which doefab may replace it."""
    folder = Path(folder)
    if not folder.exists() or (folder.is_dir() and not any(folder.iterdir())):
        return True
    marker = read_marker(folder)
    return marker is not None and marker.get("kind") == kind and all(marker.get(k) == v for k, v in fields.items())


class OutputDir:
    """The output folder of one run of a command of kind ``kind`` (``"masks"``, ``"design"``, ...).

    Construction validates (no file is touched): ``path`` must not be a file; an existing non-empty folder
    must carry this kind's ownership marker and then needs ``replace=True`` (``--force``/``--resume``); the folder (or its nearest existing parent) must be
    writable. ``create()`` makes it and writes the marker; ``discard()`` removes what ``create`` made.
    """

    def __init__(self, path: str | Path, kind: str, replace: bool = False, flag: str = "--out",
                 replace_flag: str = "--force"):
        self.path, self.kind = Path(path), kind
        self.created: list[Path] = []
        p = self.path
        if path is None or str(path).strip() == "":
            raise DoefabError(f"{flag} is empty: give a folder path")
        if p.exists() and not p.is_dir():
            raise DoefabError(f"{flag} {p} is an existing file, not a folder: give a new or empty folder path")
        self.existing = p.is_dir() and any(p.iterdir())
        if self.existing:
            marker = read_marker(p)
            if not owned_by_doefab(p, kind):
                other = (f" (it holds a doefab {marker.get('kind')} output)" if marker else
                         f" (it has no {MARKER} ownership marker)")
                raise DoefabError(f"{flag} {p} is a non-empty folder that is not a doefab {kind} output{other}: "
                                  f"doefab never replaces other files, even with {replace_flag}; choose a new "
                                  f"or empty folder")
            if not replace:
                raise DoefabError(f"{flag} {p} already holds a doefab {kind} output: pass {replace_flag} to "
                                  f"replace it, or choose another folder")
        anc = _nearest_existing(p)
        if not anc.is_dir():
            raise DoefabError(f"{flag} {p}: {anc} is a file, so no folder can be made under it")
        read_only_fs = bool(os.statvfs(anc).f_flag & os.ST_RDONLY)
        if read_only_fs or not os.access(anc, os.W_OK | os.X_OK):
            why = "read-only file system" if read_only_fs else "permission denied"
            raise DoefabError(f"{flag} {p}: cannot write in {anc} ({why}): choose a writable folder")

    def create(self) -> Path:
        """Make the folder (recording which folders this run created) and write the marker."""
        missing = []
        q = self.path.absolute()
        while not q.exists():
            missing.append(q)
            q = q.parent
        for d in reversed(missing):
            d.mkdir()
            apply_umask(d)
            self.created.append(d)
        if read_marker(self.path) != {"kind": self.kind, "written_by": "doefab"}:
            mark_folder(self.path, self.kind)
        return self.path

    def discard(self) -> None:
        """Remove the folders this run created (deepest first); a folder that existed before is kept."""
        if self.created:
            shutil.rmtree(self.created[0], ignore_errors=True)
        self.created = []


def read_toml(path: str | Path, what: str) -> dict:
    """A TOML file as a dict, or one clear error (missing file, not TOML) naming ``what`` it was meant to be."""
    import tomllib

    p = Path(path)
    if p.is_dir():
        raise DoefabError(f"{what} {p} is a folder: give the path of a TOML file")
    if p.exists() and not p.is_file():
        raise DoefabError(f"{what} {p} is not a regular file: give the path of a TOML file")
    if not p.is_file():
        raise DoefabError(f"{what} {p} not found")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8-sig"))  # a byte-order mark (some editors write one)
    except UnicodeDecodeError:
        raise DoefabError(f"{what} {p} is not UTF-8 text, as a TOML file is: give a TOML file, saved as UTF-8") from None
    except tomllib.TOMLDecodeError as exc:
        raise DoefabError(f"{p} is not valid TOML ({exc})") from None


def sources_sha256(root: str | Path, packages: tuple[str, ...]) -> str:
    """SHA-256 of the Python sources of ``packages`` (folders under ``root``), by relative path and content: a
    key that changes with the code that computes something, so a result of another version is not reused."""
    import hashlib

    root = Path(root)
    h = hashlib.sha256()
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def cache_root() -> Path:
    """Where doefab keeps what it computes once and reuses (``$DOEFAB_CACHE``, else ``$XDG_CACHE_HOME/doefab``,
    else ``~/.cache/doefab``), read at call time."""
    if os.environ.get("DOEFAB_CACHE"):
        return Path(os.environ["DOEFAB_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "doefab"
