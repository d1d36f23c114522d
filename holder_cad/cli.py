"""``python -m holder_cad ...``: the holder's command line, which is ``doefab holder ...`` (``doefab.cli.holder``;
millimetres).

Example: python -m holder_cad --out out/holder --set thread_diameter_mm=52
"""

from __future__ import annotations

import sys


def main(argv=None) -> int:
    """``python -m holder_cad ...`` is ``doefab holder ...`` (the same checks, errors and exit statuses)."""
    from doefab.cli import main as doefab_main

    return doefab_main(["holder", *(sys.argv[1:] if argv is None else argv)])
