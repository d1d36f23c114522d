"""Every public name's docstring examples run as written and print what they show (doctest)."""

import doctest
import inspect

import pytest

import doefab

# every public function and class (the constants, TASKS or FUSED_SILICA, are data: their pages describe them)
CORE = tuple(n for n in doefab.__all__ if inspect.isfunction(getattr(doefab, n)) or inspect.isclass(getattr(doefab, n)))


def _run_examples(obj, name: str) -> tuple[int, int]:
    """(examples, failures) of ``obj``'s own docstring examples, run as this test runs them."""
    tests = doctest.DocTestFinder(recurse=False).find(obj, name, globs={})
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for t in tests:
        runner.run(t, out=lambda text: None)
    return sum(len(t.examples) for t in tests), runner.failures


@pytest.mark.parametrize("name", CORE)
def test_each_public_name_has_an_example_that_runs_as_written(name):
    examples, failures = _run_examples(getattr(doefab, name), name)
    assert examples >= 2, f"doefab.{name}'s docstring has no Example section with >>> lines"
    assert failures == 0, f"doefab.{name}'s example printed something else than it shows"


def test_a_wrong_example_is_caught_and_a_missing_one_counted():
    """The helper above counts an example whose shown output differs as a failure, and a docstring without
    examples as none (so the test above can fail either way)."""
    def wrong():
        """
        >>> 1 + 1
        3
        """

    def bare():
        """No example."""

    assert _run_examples(wrong, "wrong") == (1, 1)
    assert _run_examples(bare, "bare") == (0, 0)
