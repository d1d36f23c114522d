"""Parts judged side by side (``tolerance.pool``): the same results keyed as asked, in worker processes on one
torch thread each (the studies' network passes sent there: ``test_study``)."""

import os

from doefab.tolerance import pool


def _square_where(x):
    """x², the process and torch threads that computed it (module level: a worker unpickles it by name)."""
    import torch

    return x * x, os.getpid(), torch.get_num_threads()


def test_a_pool_gives_what_the_process_gives_keyed_as_asked():
    calls = {("a", i): (i,) for i in range(6)}
    here, there = {}, {}
    pool.run_calls(_square_where, calls, lambda k, r: here.update({k: r}), workers=1)
    pool.run_calls(_square_where, calls, lambda k, r: there.update({k: r}), workers=2)
    assert {k: v[0] for k, v in here.items()} == {k: v[0] for k, v in there.items()} == {
        ("a", i): i * i for i in range(6)}
    assert {v[1] for v in here.values()} == {os.getpid()}  # in process
    assert os.getpid() not in {v[1] for v in there.values()} and {v[2] for v in there.values()} == {1}


def test_network_parts_take_one_worker_per_core_and_never_more_than_parts(monkeypatch):
    monkeypatch.setattr(pool.os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    assert pool.network_workers(5) == 2 and pool.network_workers(1) == 1
    assert pool.network_workers(5, cuda=True) == 1  # the GPU computes a part's PSFs in parallel
    monkeypatch.setattr(pool.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    assert pool.network_workers(3) == 3
    monkeypatch.setattr(pool.os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert pool.network_workers(5) == 1
