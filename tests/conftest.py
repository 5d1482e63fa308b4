"""Shared paths for the tests: the project's own files, and ../shared/testdata when present."""

from __future__ import annotations

import atexit
import fcntl
import os
import shutil
import tempfile
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


# Side by side (pytest -n), two workers may run systems of the same name: each worker gets its own
# runtime directory, so their control sockets (XDG_RUNTIME_DIR/hapticop/NAME.sock) never meet.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix=f"hapticop-{os.environ['PYTEST_XDIST_WORKER']}-")
    atexit.register(shutil.rmtree, os.environ["XDG_RUNTIME_DIR"], ignore_errors=True)


# the shipped and pinned compositions on two hosts name key directories beside them that no checkout
# holds (keys are never committed): made once, as `hapticop hosts keys FILE` would, and made again
# when something is wrong with them (expired, or a host's addresses changed)
WITH_KEYS = (SYSTEMS / "teleop.yaml", CORPUS / "valid" / "valid-two-hosts.yaml")


@pytest.fixture(scope="session", autouse=True)
def link_keys() -> None:
    from hapticop.cli.hosts import keys_for
    from hapticop.network import keys
    from hapticop.validation import validate_path
    from hapticop.validation.security import key_directory

    # test processes running side by side (pytest -n) make them once: the first takes the lock
    with open(ROOT / "tests" / ".keys.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        for file in WITH_KEYS:
            validated = validate_path(file)
            composition = validated.graph.loaded.composition
            directory = key_directory(validated.source, composition)
            wrong = any(keys.problems(directory, name, [keys.endpoint_address(e) for e in host.endpoints])
                        for name, host in composition.hosts.items())
            if wrong:
                keys_for(file, force=True, new_ca=True)


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
