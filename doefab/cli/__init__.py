"""The ``doefab`` command line: one subcommand per stage (``doefab SUBCOMMAND --help``).

Every subcommand's failures pass through ``main``: one line on stderr and a distinct exit status —
0 success, 1 internal error (a bug: ``--debug`` shows the traceback), 2 usage or input error, 3 a product
that fails its own checks (mask verification, holder checks), 130 interrupted by Ctrl-C and 143 stopped by
SIGTERM (``timeout``, a cancelled CI job, ``kill``), both with how to resume where a run can. An output
folder the run created is removed on failure (a design's checkpoint is kept).
"""

from __future__ import annotations

import argparse
import errno
import signal
import sys
import traceback
from pathlib import Path

from doefab.cli._args import OneLineParser
from doefab.cli._exits import (EXIT_CHECK, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_OK, EXIT_TERMINATED, EXIT_USAGE,
                               Terminated)

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE", "EXIT_CHECK", "EXIT_INTERRUPTED",
           "EXIT_TERMINATED", "Terminated"]



def _on_sigterm(signum, frame):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second SIGTERM must not cut the clean-up short
    raise Terminated()


def _handle_sigterm():
    """Route SIGTERM to ``Terminated``; returns the previous handler (None outside the main thread)."""
    try:
        return signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread: leave signals alone
        return None

DESCRIPTION = """\
doefab designs a split-aperture diffractive optical element (DOE) for your
camera and takes it to the fab: it optimises the coded half of the aperture
for a task (HDR, spectra or depth), quantizes it to the fab's levels, writes
and verifies the photomasks, builds a 3D-printable holder, reconstructs the
two captures with networks and judges fabricated parts. Start with `doefab
scene new`, check the scene with `doefab doctor`, then `doefab run` it;
`doefab SUBCOMMAND --help` tells more of each."""

EPILOG = """\
exit status: 0 done, 2 bad input (the message names the fix), 3 a product that
fails its own checks, 130 / 143 interrupted (rerun the same command to
continue), 1 an internal error (--debug shows it)."""

# API names that may appear in a library message, and what a command-line user sets instead
_CLI_NAMES = (
    ("(pupil_oversample ≥", "(--pupil-oversample ≥"),
    ("pupil_oversample ≥", "--pupil-oversample ≥"),
    ("resample it or set Camera.doe_pixels", "resample it or choose the --preset whose grid it was made for"),
    ("enlarge die_m", "raise --die-mm"),
    ("at most the pitch (cd_m)", "at most the pitch (--cd-um)"),
    ("mm (die_chamfer_m)", "mm (--die-chamfer-mm)"),
    (", bring the depths nearer the focus, or pass PSFPlan(check=False) to accept PSFs cut by the window",
     ", or bring the depths nearer the focus"),
)


class _TopFormatter(argparse.RawDescriptionHelpFormatter):
    """The top-level help: the paragraphs as written, and each subcommand on one line of 80 columns."""

    def __init__(self, prog):
        super().__init__(prog, max_help_position=20, width=80)
        self._action_max_length = 16  # room for the longest subcommand name ("tolerance") beside its help


def _cache_fix(filename) -> str:
    """The fix for a cache folder that cannot be read or written (a read-only home): another one, by
    ``$DOEFAB_CACHE``; "" where ``filename`` is not the cache or a folder above it."""
    from doefab.io import cache_root

    if not filename:
        return ""
    path, cache = Path(filename).absolute(), cache_root().absolute()
    if path == cache or path in cache.parents or cache in path.parents:
        return f"; doefab keeps its cache in {cache}: set $DOEFAB_CACHE to a folder you can write"
    return ""


def build_parser() -> argparse.ArgumentParser:
    from doefab.cli import (calibrate, demo, design, diagnose, doctor, evaluate, finetune, holder, masks, psf,
                            reconstruct, run, scene, tolerance, train)

    parser = OneLineParser(prog="doefab", description=DESCRIPTION, epilog=EPILOG, formatter_class=_TopFormatter)
    parser.add_argument("--version", action="version", version=f"doefab {__import__('doefab').__version__}")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND", parser_class=OneLineParser)
    for module in (run, scene, doctor, demo, psf, design, masks, holder, train, evaluate, finetune, tolerance,
                   calibrate, diagnose, reconstruct):
        module.register(sub)
    for name, subparser in sub.choices.items():
        subparser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                               help="show the Python traceback of an error")
        _plain_texts(subparser)
    return parser


def _plain_texts(parser) -> None:
    """The descriptions are the modules' docstrings, written for the API pages: a terminal shows ``x`` as x, in
    ``parser`` and the parsers of its own subcommands (``scene new``)."""
    parser.description = _plain(parser.description)
    parser.epilog = _plain(parser.epilog)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                _plain_texts(child)


def _plain(text: str | None) -> str | None:
    """reStructuredText's inline literals (``x``) and roles (:doc:`x`, :func:`x`) as plain text."""
    import re

    if text is None:
        return None
    return re.sub(r"(?::[a-z]+:)?`{1,2}([^`]+?)`{1,2}", r"\1", text)


def _one_line(text: str) -> str:
    line = " ".join(str(text).split())
    for api, flag in _CLI_NAMES:
        line = line.replace(api, flag)
    return line


def main(argv: list[str] | None = None) -> int:
    from doefab.errors import CheckFailed, DoefabError
    from holder_cad.params import HolderError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):  # a usage error: the help, on stderr, says what to give
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    prog = f"doefab {args.command}"
    status, message, error = EXIT_OK, "", None
    previous = _handle_sigterm()
    try:
        _refuse_empty_values(parser, args)
        from doefab._devices import using_device
        from doefab._memory import keep_freed_memory

        keep_freed_memory()  # a command's blocks of megabytes are reused, not faulted in afresh (same numbers)

        with using_device(getattr(args, "device", None)):  # --device: what device=None means in this command
            return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:
        status, what = ((EXIT_TERMINATED, "terminated (SIGTERM)") if isinstance(exc, Terminated)
                        else (EXIT_INTERRUPTED, "interrupted"))
        hint, keep = getattr(args, "resume_hint", None), getattr(args, "keep_on_failure", None)
        hint = hint() if callable(hint) else hint  # a hint that depends on what the run saved before it stopped
        kept = not _will_discard(args) and (keep is None or keep())  # the hint only where its file is there
        message = what + "; " + (hint if hint and kept else "nothing was kept")
    except CheckFailed as exc:
        error = exc
        status, message = EXIT_CHECK, f"check failed: {exc}"
    except (DoefabError, HolderError) as exc:
        error = exc
        status, message = EXIT_USAGE, f"error: {exc}"
    except OSError as exc:  # disk full, permissions, a path that vanished: the user's environment
        error = exc
        full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
        where = f" {exc.filename}" if getattr(exc, "filename", None) else _output_folder(args) if full else ""
        fix = ("; free space on that disk, or write elsewhere (--out; $DOEFAB_CACHE for the cache)" if full
               else _cache_fix(exc.filename))
        status, message = EXIT_USAGE, f"error: cannot read or write{where}: {exc.strerror or exc}{fix}"
    except MemoryError:
        status, message = EXIT_USAGE, _out_of_memory(args)
    except Exception as exc:  # noqa: BLE001 - a bug: one line, the traceback on request
        error = exc
        if _is_out_of_memory(exc):  # torch's allocators (CPU and CUDA) raise a RuntimeError
            status, message = EXIT_USAGE, _out_of_memory(args)
        else:
            status, message = EXIT_INTERNAL, (f"internal error: {exc.__class__.__name__}: {exc} (rerun with "
                                              f"--debug for the traceback, and please report it)")
    finally:
        if status != EXIT_OK:
            _discard_outputs(args)
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    if getattr(args, "debug", False) and error is not None:
        traceback.print_exception(error)
    print(f"{prog}: {_one_line(message)}", file=sys.stderr)
    return status


def _is_out_of_memory(exc: BaseException) -> bool:
    """Whether ``exc`` is an allocator's refusal (torch's CPU "can't allocate memory", CUDA "out of memory")."""
    text = str(exc)
    return isinstance(exc, RuntimeError) and ("can't allocate memory" in text or "out of memory" in text)


def _out_of_memory(args) -> str:
    """The out-of-memory error, with the command's own fix (``args.memory_hint``) where it set one."""
    hint = getattr(args, "memory_hint", None) or "use a smaller kernel, grid or fewer wavelengths"
    return f"error: out of memory: {hint}"


def _refuse_empty_values(parser, args) -> None:
    """A flag given an empty value (``--design ""``) is a mistake, not "use the default": refuse it by name."""
    from doefab.errors import DoefabError

    sub = parser._subparsers._group_actions[0].choices[args.command]
    for action in sub._actions:
        value = getattr(args, action.dest, None)
        if action.option_strings and isinstance(value, str) and not value.strip():
            flag = max(action.option_strings, key=len)
            raise DoefabError(f"{flag} is empty: give a value (see doefab {args.command} --help)")


def _output_folder(args) -> str:
    """" a file under FOLDER" for the run's output folder (a writer that names no file: a stream, a figure)."""
    from pathlib import Path

    out = getattr(getattr(args, "outdir", None), "path", None) or getattr(args, "out", None)
    return f" a file under {Path(out).absolute()}" if out else ""


def _will_discard(args) -> bool:
    """Whether a failed run's output goes: it made a folder, and it has nothing to resume from."""
    out, keep = getattr(args, "outdir", None), getattr(args, "keep_on_failure", None)
    return out is not None and bool(out.created) and not (keep is not None and keep())


def _discard_outputs(args) -> None:
    if _will_discard(args):
        args.outdir.discard()


if __name__ == "__main__":
    sys.exit(main())
