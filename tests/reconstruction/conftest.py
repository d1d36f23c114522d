"""Fixtures of the reconstruction tests."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rv():
    """``benchmarks/real_validation.py`` as a module (the measured-data page's code)."""
    spec = importlib.util.spec_from_file_location("real_validation", ROOT / "benchmarks" / "real_validation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
