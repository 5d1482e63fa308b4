"""Shared paths for the tests: the project's own files, and ../shared/testdata when present."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SYSTEMS = ROOT / "systems"
CORPUS = Path(__file__).resolve().parent / "corpus"
SHARED_TESTDATA = ROOT.parent / "shared" / "testdata"


@pytest.fixture
def hallway_text() -> str:
    return (SYSTEMS / "hallway.yaml").read_text()


@pytest.fixture(scope="session")
def hallway_text_cached() -> str:
    """Session-scoped, so hypothesis may use it across examples."""
    return (SYSTEMS / "hallway.yaml").read_text()
