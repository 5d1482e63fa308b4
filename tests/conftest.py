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


@pytest.fixture
def figure(request):
    """Keep a measured figure (a speed, a peak) with the test's report instead of printing it into the
    test output: `pytest -v` lists them all at the end, the quiet default shows none."""
    def keep(text: str) -> None:
        request.node.user_properties.append(("figure", text.strip()))
    return keep


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if config.option.verbose <= 0:
        return
    figures = [(report.nodeid, value) for report in terminalreporter.stats.get("passed", [])
               for name, value in report.user_properties if name == "figure"]
    if figures:
        terminalreporter.section("figures")
        for nodeid, text in figures:
            terminalreporter.write_line(f"{nodeid}: {text}")
