"""Where a study's Monte Carlo parts run: the scheduler's text is checked as the same rule at the command line, in
a scene and in the API, and a ``tcp://`` scheduler must answer before any work."""

import socket

import pytest

from doefab.errors import DoefabError
from doefab.tolerance.schedulers import MAX_WORKERS, check_reachable, parse_scheduler


@pytest.mark.parametrize("text, workers", [("local:1", 1), (f"local:{MAX_WORKERS}", MAX_WORKERS),
                                           ("tcp://10.0.0.5:8786", None), ("tcp://node-3.lab:1", None),
                                           ("tcp://[::1]:65535", None)])
def test_the_two_forms_parse(text, workers):
    assert parse_scheduler(text) == workers


@pytest.mark.parametrize("text, words", [("local:0", "N = 1..64"), (f"local:{MAX_WORKERS + 1}", "N = 1..64"),
                                         ("local:two", "N = 1..64"), ("tcp://nohost", "tcp://HOST:PORT"),
                                         ("tcp://h:0", "tcp://HOST:PORT"), ("tcp://h:70000", "tcp://HOST:PORT"),
                                         ("udp://h:8786", "tcp://HOST:PORT"), ("", "tcp://HOST:PORT"),
                                         (2, "give text")])
def test_anything_else_is_one_error_naming_the_value_and_the_forms(text, words):
    with pytest.raises(DoefabError, match="^--scheduler ") as e:
        parse_scheduler(text, "--scheduler")
    assert repr(text) in str(e.value) and words in str(e.value)


def test_a_tcp_scheduler_must_answer():
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        check_reachable(f"tcp://127.0.0.1:{port}", "tolerance.scheduler")  # something listens: passes
    # the port is closed now: nothing answers there
    with pytest.raises(DoefabError, match=r"^tolerance.scheduler 'tcp://127.0.0.1:\d+': no Dask scheduler answers"):
        check_reachable(f"tcp://127.0.0.1:{port}", "tolerance.scheduler", timeout_s=2)
    check_reachable("local:2")  # started by the study: nothing to reach
    check_reachable(None)


def test_run_study_refuses_bad_runners_before_any_work(tmp_path):
    from doefab.tolerance.errors import load_budget
    from doefab.tolerance.report import run_study

    for kw, words in [({"workers": 0}, "1..64"), ({"workers": 2.5}, "whole number"),
                      ({"workers": 2, "scheduler": "local:2"}, "give one"), ({"scheduler": "local:x"}, "N = 1..64")]:
        with pytest.raises(DoefabError, match=words):
            run_study(tmp_path / "no design", load_budget(None), tmp_path / "out", samples=2, progress=False, **kw)
    assert not (tmp_path / "out").exists()
