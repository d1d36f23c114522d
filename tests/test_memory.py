"""Freed memory kept for reuse (``doefab.keep_freed_memory``): the kernel's page-fault count shows it, and every
``doefab`` command applies it."""

import platform
import subprocess
import sys

import pytest

import doefab._memory
from doefab.cli import main

GLIBC = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"

# a block of 64 MiB allocated, touched and freed, then allocated and touched again: the page faults of the
# second touch (the kernel's count, getrusage)
_SECOND_TOUCH = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    import doefab
    assert doefab.keep_freed_memory()
a = np.ones(64 << 17); del a
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
a = np.ones(64 << 17)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _second_touch_faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", _SECOND_TOUCH, mode], capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(not GLIBC, reason="mallopt is glibc's: elsewhere keep_freed_memory does nothing")
def test_a_freed_block_is_reused_without_page_faults():
    """By default glibc returns a freed 64 MiB block to the system, and touching a new one faults every page in
    again (at least one per 2 MiB huge page: 32); kept, the block comes back with its pages in place."""
    assert _second_touch_faults("default") >= 32
    assert _second_touch_faults("keep") <= 8


def test_every_command_keeps_freed_memory(monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(doefab._memory, "keep_freed_memory", lambda: calls.append(1) or True)
    assert main(["scene", "keys"]) == 0
    assert calls == [1]
    assert "task" in capsys.readouterr().out


def test_a_memory_share_bounds_what_a_process_counts_as_available(monkeypatch):
    """``$DOEFAB_MEMORY_BYTES`` (each scene of ``doefab run --jobs`` is given its part): what this process may still
    take is no more than the share, nor more than the machine has; no share, or a share that is not a whole number
    ≥ 1: as before."""
    from doefab._memory import SHARE_ENV, available_bytes

    if platform.system() != "Linux":
        pytest.skip("reads /proc: Linux only")
    for nothing in ("nonsense", "0", "-5"):
        monkeypatch.setenv(SHARE_ENV, nothing)
        assert available_bytes() > 2**28  # the machine's: more than the share below
    monkeypatch.setenv(SHARE_ENV, str(2**28))
    assert available_bytes() == 2**28
    monkeypatch.setenv(SHARE_ENV, str(2**62))
    assert available_bytes() < 2**62  # a share beyond the machine: the machine's
