"""The core public API's docstring examples run as written and print what they show (doctest)."""

import doctest

import pytest

CORE = ("Camera", "split_aperture_psf", "PSFPair", "optimize", "simulate_captures", "load_reconstructor")


@pytest.mark.parametrize("name", CORE)
def test_each_core_public_name_has_an_example_that_runs_as_written(name):
    import doefab

    obj = getattr(doefab, name)
    tests = doctest.DocTestFinder(recurse=False).find(obj, name, globs={})
    examples = sum(len(t.examples) for t in tests)
    assert examples >= 2, f"doefab.{name}'s docstring has no Example section with >>> lines"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for t in tests:
        runner.run(t)
    assert runner.failures == 0, f"doefab.{name}'s example printed something else than it shows"


def test_a_wrong_example_is_caught():
    """The runner above fails an example whose shown output differs (so the test can fail)."""
    def f():
        """
        >>> 1 + 1
        3
        """
    tests = doctest.DocTestFinder().find(f, "f", globs={})
    runner = doctest.DocTestRunner()
    for t in tests:
        runner.run(t, out=lambda s: None)
    assert runner.failures == 1
