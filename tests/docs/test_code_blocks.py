"""Every ```python block of the README and of the documentation pages runs as written.

A page's blocks run in order in one namespace (a page reads top to bottom: a later block uses what an earlier one
made), in a scratch folder. A block preceded by ``<!-- not-run: REASON -->`` is skipped; ``NOT_RUN`` lists those
exceptions, so a new one is a visible change of this file. Only Python blocks are executed: the ``doefab``
commands the guide shows are run by the site's build (``docs/_ext``), the shell blocks are the scripts' own.
"""

import re
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FENCE = re.compile(r"^(?P<indent>[ \t]*)```python[ \t]*\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
SKIP = re.compile(r"<!--\s*not-run:\s*(?P<why>[^>]*?)\s*-->\s*$")
NOT_RUN: dict[str, str] = {}  # "page: first line of the block" → why it cannot run in the test suite


def pages() -> list[Path]:
    docs = [p for p in sorted((REPO / "docs").rglob("*.md")) if not {"_build", "_generated"} & set(p.parts)]
    return [REPO / "README.md"] + docs


def blocks(page: Path) -> list[tuple[int, str, str | None]]:
    """(line number, dedented source, why it is not run or None) of each ```python block of ``page``."""
    text = page.read_text(encoding="utf-8")
    out = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        skip = SKIP.search(before)
        out.append((text.count("\n", 0, m.start()) + 1, textwrap.dedent(m.group("body")),
                    skip.group("why") if skip else None))
    return out


PAGES = [p for p in pages() if blocks(p)]


def test_the_pages_with_python_blocks_are_found():
    """The README and the guide's reconstruction page hold Python examples: the extraction sees them."""
    names = {p.relative_to(REPO).as_posix() for p in PAGES}
    assert {"README.md", "docs/guide/reconstruction.md"} <= names
    assert sum(len(blocks(p)) for p in PAGES) >= 3


def test_a_block_marked_not_run_is_skipped_and_listed(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n\n```python\nx = 1\n```\n\n<!-- not-run: needs a camera -->\n```python\nraise SystemExit\n"
                    "```\n\n- item\n\n  ```python\n  y = x + 1\n  ```\n")
    got = blocks(page)
    assert [(line, why) for line, _, why in got] == [(3, None), (8, "needs a camera"), (14, None)]
    assert got[2][1] == "y = x + 1\n"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_python_block_runs_as_written(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__doc_block__"}
    rel = page.relative_to(REPO).as_posix()
    for line, source, why in blocks(page):
        key = f"{rel}: {source.splitlines()[0] if source.strip() else ''}"
        if why is not None:
            assert key in NOT_RUN, f"{rel}:{line} is marked not-run ({why}) but is not listed in NOT_RUN"
            continue
        try:
            exec(compile(source, f"{rel}:{line}", "exec"), namespace)
        except Exception as exc:  # noqa: BLE001 - any failure of a documented example is the finding
            pytest.fail(f"{rel}, the block at line {line}, fails as written: {type(exc).__name__}: {exc}")
