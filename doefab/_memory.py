"""How a doefab process handles its memory: freed blocks kept for reuse (``keep_freed_memory``).

doefab's computations allocate and free blocks of megabytes many times a second (an FFT canvas per wavelength,
a capture per scene, a network's activations). glibc serves each such block from a fresh ``mmap`` and returns
it when freed, so every allocation faults its pages in again, zero-filled by the kernel. ``keep_freed_memory``
switches that off for the process; ``MALLOC_ENV`` is the same setting for a worker process that doefab starts
(glibc reads it when the process starts). Every ``doefab`` command applies it (``doefab.cli.main``), and so do
the tolerance workers. An API user applies it with one call.
"""

from __future__ import annotations

__all__ = ["keep_freed_memory", "available_bytes", "MALLOC_ENV", "SHARE_ENV", "memory_share"]

_TRIM_NEVER = 2**31 - 1  # bytes: the largest value mallopt takes (an int)
# glibc's environment names for the two settings keep_freed_memory makes: no mmap'd blocks, no heap trimming
MALLOC_ENV = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(_TRIM_NEVER)}
_MALLOC_SET = False
#: the memory, in bytes, that a process and the workers it starts may count on (``doefab run --jobs`` gives each
#: scene its part of what was available); ``available_bytes`` counts no more than it
SHARE_ENV = "DOEFAB_MEMORY_BYTES"


def keep_freed_memory() -> bool:
    """Let this process reuse the memory it frees instead of returning it to the system and faulting it back in
    (glibc's ``mallopt``: no mmap'd blocks, no heap trimming). The numbers are unchanged, only the time: with the
    default settings the page faults of fresh blocks cost about a quarter to a third of a tolerance part
    (``benchmarks/judge_profile.py``) and up to half of a 512² spectra or depth reconstruction
    (``benchmarks/reconstruction_speed.py``). The process keeps its peak memory until it exits. Returns whether
    it applied (False off glibc); calling it again does nothing.

    Example:
        >>> import doefab
        >>> doefab.keep_freed_memory() in (True, False)
        True
    """
    global _MALLOC_SET
    if _MALLOC_SET:
        return True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        ok = libc.mallopt(-4, 0) == 1 and libc.mallopt(-1, _TRIM_NEVER) == 1  # M_MMAP_MAX, M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        return False
    _MALLOC_SET = bool(ok)
    return _MALLOC_SET


def available_bytes() -> int | None:
    """The memory this process can still take, in bytes: the kernel's ``MemAvailable`` (``/proc/meminfo``),
    lowered to the room left under each cgroup memory limit above this process (v2: ``memory.max`` −
    ``memory.current``; v1: ``memory.limit_in_bytes`` − ``memory.usage_in_bytes``; the reclaimable inactive page
    cache counted as free) inside a container or a batch job, and to this process's share ``$DOEFAB_MEMORY_BYTES``
    where that is set (``SHARE_ENV``; each scene of ``doefab run --jobs`` is given one); None where
    nothing can be read (not Linux, no share).

    Example:
        >>> from doefab._memory import available_bytes
        >>> n = available_bytes()
        >>> n is None or n > 0
        True
    """
    from pathlib import Path

    found = []
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    found += _cgroup_rooms(Path("/sys/fs/cgroup"))
    share = memory_share()
    if share is not None:
        found.append(share)
    return min(found) if found else None


def memory_share() -> int | None:
    """``$DOEFAB_MEMORY_BYTES`` where set to a whole number of bytes ≥ 1, else None. Example: ``memory_share()``
    is None unless a share was given (``doefab run --jobs`` gives each scene side by side one)."""
    from doefab._devices import env_count

    return env_count(SHARE_ENV)


def _cgroup_rooms(root) -> list[int]:
    """The room under each cgroup v2 memory limit from this process's group up to ``root``, and under a cgroup v1
    memory limit (bytes)."""
    try:
        with open("/proc/self/cgroup") as f:
            rel = next(line[3:].strip() for line in f if line.startswith("0::"))
    except (OSError, StopIteration):
        rel = "/"
    group, rooms = root / rel.lstrip("/"), []
    for d in (group, *group.parents):
        try:
            limit = (d / "memory.max").read_text().strip()
            if limit != "max":
                rooms.append(_room(int(limit), d, "memory.current", "inactive_file"))
        except (OSError, ValueError):
            pass
        if d == root:
            break
    try:  # cgroup v1: the memory controller's own group as this process sees it
        v1 = root / "memory"
        limit = int((v1 / "memory.limit_in_bytes").read_text())
        if limit < 2**62:
            rooms.append(_room(limit, v1, "memory.usage_in_bytes", "total_inactive_file"))
    except (OSError, ValueError):
        pass
    return rooms


def _room(limit: int, group, usage: str, inactive: str) -> int:
    """Bytes left under ``limit`` in a cgroup folder: the limit less its ``usage`` file's count, the reclaimable
    page cache (``memory.stat``'s ``inactive`` entry) counted as free."""
    stat = dict(line.split() for line in (group / "memory.stat").read_text().splitlines())
    return max(0, limit - int((group / usage).read_text()) + int(stat.get(inactive, 0)))
