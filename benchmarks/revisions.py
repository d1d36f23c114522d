"""Before-and-after timings in one run: a benchmark measured again with the package as of another git revision.

``measure_at(rev, script, argv)`` checks ``rev`` out into a temporary worktree, runs ``script argv
--measure-only`` in a subprocess with ``DOEFAB_BENCH_CODE`` pointing at it (the script puts that folder first on
``sys.path``) and returns ``(short revision, the JSON the script printed)``. The worktree is removed afterwards.
``measure_at(None, ...)`` runs the same in a fresh process on this checkout, so both codes start alike.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def code_root() -> str:
    """The package folder a benchmark measures: a baseline's worktree, or this checkout."""
    return os.environ.get("DOEFAB_BENCH_CODE", str(ROOT))


def add_arguments(ap, baseline: str | None = "HEAD", help: str = "git revision timed beside this code ('none': "
                  "skip)") -> None:
    """The options every before-and-after benchmark takes: --threads, --baseline, --results, --measure-only."""
    import argparse

    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--baseline", default=baseline, help=help)
    ap.add_argument("--results", default=str(RESULTS))
    ap.add_argument("--measure-only", action="store_true", help=argparse.SUPPRESS)


def turns(baseline: str, rounds: int = 1, start: int = 0):
    """The codes in the order they take turns: ``baseline`` and this checkout (None), which goes first alternating
    from round to round (``start``: the first round's number); the baseline left out when it is "none"."""
    codes = [baseline, None] if baseline != "none" else [None]
    for r in range(start, start + rounds):
        yield from codes[::-1] if r % 2 else codes


def median_time(fn, repeats=3):
    """Median wall time of ``repeats`` calls of ``fn`` (seconds)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def measure_at(rev: str | None, script: str, argv: list[str]) -> tuple[str, dict]:
    """(short revision, result) of ``script argv --measure-only`` run in a fresh process with the package as of
    git ``rev`` (None: this checkout as it is, uncommitted changes included; its revision is HEAD's)."""
    with worktree(rev) as tree:
        return revision(tree), _run(script, argv, tree)


@contextmanager
def worktree(rev: str | None):
    """The package folder as of git ``rev``, checked out for the ``with`` block (None: this checkout)."""
    if rev is None:
        yield ROOT
        return
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), rev], check=True,
                       capture_output=True)
        try:
            yield tree
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)


def revision(tree: Path) -> str:
    """The short git revision of the checkout at ``tree``, with "+uncommitted" when tracked files differ from it."""
    sha = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], check=True, capture_output=True,
                         text=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"], check=True,
                           capture_output=True, text=True).stdout.strip()
    return sha + ("+uncommitted" if dirty else "")


def same_code_warning(baseline: str, this: str) -> None:
    """Say so on stderr when the baseline is this very code (e.g. ``--baseline HEAD`` on a clean checkout)."""
    if baseline == this:
        print(f"warning: the baseline {baseline} is this code: pass --baseline REV of the code to compare with",
              file=sys.stderr, flush=True)


def _run(script: str, argv: list[str], tree: Path) -> dict:
    env = {**os.environ, "DOEFAB_BENCH_CODE": str(tree)}
    out = subprocess.run([sys.executable, script, *argv, "--measure-only"], check=True, capture_output=True,
                         text=True, env=env).stdout
    return json.loads(out.strip().splitlines()[-1])
