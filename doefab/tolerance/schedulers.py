"""Where a tolerance study's Monte Carlo parts run outside its own process, as a user names it: a local process
pool of N workers (``--workers N``, the scene's ``tolerance.workers``) or a Dask scheduler (``--scheduler``, the
scene's ``tolerance.scheduler``): ``local:N``, a Dask ``LocalCluster`` of N workers started for the study, or
``tcp://HOST:PORT``, a running Dask scheduler whose workers judge the parts.

One check of each, shared by the command line, the scene file and the API: the text's form when it is given
(``parse_scheduler``), that at most one of the two is given (``runner_conflict``), and, before any work, that a
``tcp://`` scheduler answers (``check_reachable``).
"""

from __future__ import annotations

import re

from doefab.errors import DoefabError

__all__ = ["MAX_WORKERS", "parse_scheduler", "check_reachable", "parts_at_once", "runner_conflict"]

MAX_WORKERS = 64  # local worker processes (a pool's or a LocalCluster's) one study starts at most

_TCP = re.compile(r"tcp://(\[[^\]]+\]|[^:/\s\[\]]+):(\d{1,5})")


def _who(text, name: str) -> str:
    return f"{name} {text!r}".strip()


def parse_scheduler(text, name: str = "") -> int | None:
    """The worker count N of ``local:N`` (N = 1..``MAX_WORKERS``), None for ``tcp://HOST:PORT`` (PORT 1..65535);
    anything else is one ``DoefabError`` naming the value (after ``name``, e.g. ``"--scheduler"``) and the two
    forms it takes.

    Example:
        >>> parse_scheduler("local:4"), parse_scheduler("tcp://10.0.0.5:8786")
        (4, None)
    """
    example = "e.g. local:2 or tcp://127.0.0.1:8786"
    if not isinstance(text, str):
        raise DoefabError(f"{_who(text, name)} is not a Dask scheduler: give text, local:N or tcp://HOST:PORT "
                          f"({example})")
    kind, _, rest = text.partition(":")
    if kind == "local":
        if rest.isdigit() and 1 <= int(rest) <= MAX_WORKERS:
            return int(rest)
        raise DoefabError(f"{_who(text, name)}: local:N takes a worker count N = 1..{MAX_WORKERS} (e.g. local:2)")
    m = _TCP.fullmatch(text)
    if m is not None and 1 <= int(m.group(2)) <= 65535:
        return None
    raise DoefabError(f"{_who(text, name)} is not a Dask scheduler: give local:N (N = 1..{MAX_WORKERS} workers "
                      f"started for the study) or tcp://HOST:PORT (a running scheduler), {example}")


def runner_conflict(workers, scheduler, names: tuple[str, str] = ("workers", "scheduler")) -> str | None:
    """What is wrong when both a worker count and a scheduler are given (None: at most one is), in the words of
    the interface that took them (``names``: the flags, scene keys or arguments).

    Example:
        >>> runner_conflict(2, "local:2", ("--workers", "--scheduler"))
        '--workers and --scheduler both say where the parts run: give one'
        >>> runner_conflict(None, "local:2") is None
        True
    """
    if workers is not None and scheduler is not None:
        return f"{names[0]} and {names[1]} both say where the parts run: give one"
    return None


def check_reachable(text: str | None, name: str = "--scheduler", timeout_s: float = 5.0) -> None:
    """Refuse, before any part is judged, a ``tcp://HOST:PORT`` scheduler that accepts no connection within
    ``timeout_s`` seconds (not minutes later, after the grid study and the tornado); ``local:N`` and None pass.

    Example:
        >>> check_reachable("local:2") is None
        True
    """
    import socket

    if not text or parse_scheduler(text, name) is not None:
        return
    host, _, port = text.removeprefix("tcp://").rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise DoefabError(f"{_who(text, name)}: no Dask scheduler answers there ({exc.strerror or exc}): start one "
                          f"(dask scheduler --port {port}, then dask worker {text}) or use local:N") from None


def parts_at_once(workers: int | None, scheduler: str | None) -> int:
    """How many parts this machine judges at once: ``workers`` (None: one, as the automatic count starts no more
    workers than fit), a ``local:N`` scheduler's N, or one for a ``tcp://`` cluster, whose workers judge elsewhere
    (the tornado still judges here).

    Example:
        >>> parts_at_once(None, "local:3"), parts_at_once(2, None), parts_at_once(None, "tcp://h:8786")
        (3, 2, 1)
    """
    if scheduler:
        return parse_scheduler(scheduler) or 1
    return workers or 1
