"""The ``doefab`` command line: one subcommand per stage (``doefab SUBCOMMAND --help``)."""

from __future__ import annotations

import argparse
import sys

from doefab.errors import DoefabError
from holder_cad.params import HolderError

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    from doefab.cli import demo, design, holder, masks, psf

    parser = argparse.ArgumentParser(prog="doefab", description=__doc__)
    parser.add_argument("--version", action="version", version=f"doefab {__import__('doefab').__version__}")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND")
    for module in (demo, psf, design, masks, holder):
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except (DoefabError, HolderError) as exc:
        print(f"doefab {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
