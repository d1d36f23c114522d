"""Fixtures of the reconstruction tests."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _benchmark(name: str):
    """``benchmarks/<name>.py`` as a module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def rv():
    """``benchmarks/real_validation.py`` (the measured-data page's code)."""
    return _benchmark("real_validation")


@pytest.fixture(scope="module")
def tables():
    """``benchmarks/reconstruction_tables.py`` (the reconstruction tables' code)."""
    return _benchmark("reconstruction_tables")


@pytest.fixture(scope="module")
def hdr_candidates():
    """``benchmarks/hdr_fewer_iters.py`` (the HDR candidate page's code)."""
    return _benchmark("hdr_fewer_iters")
