"""Shared paths for the tests: the project's own files, and ../shared/testdata when present."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import settings

# The suite is deterministic: property tests draw the same examples on every run and keep
# no example database between runs (a found counterexample becomes a plain test).
settings.register_profile("hapticop", derandomize=True, database=None)
settings.load_profile("hapticop")

ROOT = Path(__file__).resolve().parent.parent
SYSTEMS = ROOT / "systems"
CORPUS = Path(__file__).resolve().parent / "corpus"
SHARED_TESTDATA = ROOT.parent / "shared" / "testdata"
FIXTURES = Path(__file__).resolve().parent / "fixtures"


@pytest.fixture
def hallway_text() -> str:
    return (SYSTEMS / "hallway.yaml").read_text()


@pytest.fixture(scope="session")
def hallway_text_cached() -> str:
    """Session-scoped, so hypothesis may use it across examples."""
    return (SYSTEMS / "hallway.yaml").read_text()
