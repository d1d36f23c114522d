"""Parts judged side by side: a local pool of worker processes, each on one torch thread, or in process.

A part judged through a network spends much of its time on one torch thread (its scenes are scored as ``doefab
evaluate`` scores them), and a part's PSFs gain less from a second thread than from a second part: measured on the
half-ring's decentered part through the depth network, 38 s on two threads in one process against 50–54 s on one
(``benchmarks/tolerance_speed.py``), so two parts at once on one thread each finish sooner. On Linux the workers are
forked: they start with what this process already holds (its judges, the error-free part's PSFs and plain half,
the coded halves a PSF-level pass computed), so nothing the parts share is computed again. Results are recorded
as each part finishes, keyed as asked; an interruption keeps the finished ones and drops the queue.
"""

from __future__ import annotations

import os

__all__ = ["run_calls", "usable_cores", "network_workers", "worker_init"]


def usable_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def network_workers(parts: int, cuda: bool = False) -> int:
    """Worker processes for ``parts`` network-judged parts: one per usable core (at most one per part), in process
    (1) on a CUDA device (the GPU computes a part's PSFs in parallel) or for a single part. A network part takes
    tens of seconds; a forked worker starts with this process's judges, so two parts already repay it."""
    cores = usable_cores()
    return 1 if cuda or cores < 2 or parts < 2 else min(cores, parts)


def worker_init():
    """A worker's set-up: one torch thread, freed memory kept, signals left to the parent (it keeps the finished
    parts and drops the queue on Ctrl-C or SIGTERM; a worker just finishes its part, or dies with the pool)."""
    import signal

    from doefab.tolerance.memory import keep_freed_memory

    os.environ["DOEFAB_WORKER"] = "1"
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    keep_freed_memory()
    import torch

    torch.set_num_threads(1)


def run_calls(fn, calls: dict, record, workers: int = 1, spawn: bool = False) -> None:
    """``record(key, fn(*args))`` for each ``key: args`` of ``calls`` as it finishes: in this process in the
    order given when ``workers`` ≤ 1, else over a local pool of ``workers`` processes (``spawn``: started fresh, as
    CUDA needs; else the platform's default, forked on Linux). ``fn`` and its arguments must pickle.

    Example: ``run_calls(evaluate_part, {0: (design, 1, errors, True, None)}, lambda k, r: out.update({k: r}), 2)``.
    """
    if workers <= 1 or len(calls) <= 1:
        from doefab.tolerance.memory import keep_freed_memory

        keep_freed_memory()
        for key, args in calls.items():
            record(key, fn(*args))
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ex = ProcessPoolExecutor(min(workers, len(calls)), initializer=worker_init,
                             mp_context=multiprocessing.get_context("spawn") if spawn else None)
    try:
        futs = {ex.submit(fn, *args): key for key, args in calls.items()}
        for f in as_completed(futs):
            record(futs[f], f.result())
    finally:  # an interruption drops the queued parts (the recorded ones stay) instead of waiting for all
        ex.shutdown(wait=True, cancel_futures=True)
