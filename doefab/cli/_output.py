"""Claiming a command's output folder before any work starts (see ``doefab.io.OutputDir``)."""

from __future__ import annotations

from doefab.io import OutputDir


def claim_output(args, kind: str, replace: bool, keep_on_failure=None, replace_flag: str = "--force") -> OutputDir:
    """Validate ``args.out`` for a ``kind`` output and register it so a failed run removes what it created."""
    out = OutputDir(args.out, kind, replace=replace, replace_flag=replace_flag)
    args.outdir = out
    args.keep_on_failure = keep_on_failure
    return out
