"""Reference data for the ropod tests: ../shared/testdata when present, else the shipped subset.

The shipped files in tests/fixtures/ropod/ are compact copies (the PDO and simulation files
trimmed to what the tests use), so the tests pass on a clean checkout; when the shared data
is there, it is what the tests read, and the copies are checked against it.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

import pytest

SHARED = Path(__file__).resolve().parent.parent.parent / "shared" / "testdata"
FIXTURES = Path(__file__).resolve().parent / "fixtures" / "ropod"

FILES = {
    "reference": "ropod/reference.json",
    "sim_candidates": "ropod/sim_candidate_results.json",
    "pdo": "ethercat/ropod_smartwheel_pdo.json",
}


@cache
def load(name: str) -> dict[str, Any]:
    """One reference file by its short name ('reference', 'sim_candidates', 'pdo')."""
    shared = SHARED / FILES[name]
    path = shared if shared.is_file() else FIXTURES / Path(FILES[name]).name
    return json.loads(path.read_text())


def _is_subset(small: Any, big: Any) -> bool:
    if isinstance(small, dict):
        return isinstance(big, dict) and all(k in big and _is_subset(v, big[k]) for k, v in small.items())
    if isinstance(small, list):
        return isinstance(big, list) and len(small) == len(big) and all(map(_is_subset, small, big))
    return small == big


@pytest.mark.parametrize("name", sorted(FILES))
def test_shipped_fixture_is_a_faithful_subset_of_the_shared_data(name):
    shared = SHARED / FILES[name]
    if not shared.is_file():
        pytest.skip("../shared/testdata is not here: no original to compare the shipped copy with")
    shipped = json.loads((FIXTURES / shared.name).read_text())
    assert _is_subset(shipped, json.loads(shared.read_text()))


def test_the_loader_finds_every_file():
    for name in FILES:
        assert load(name)


def test_the_shipped_copies_alone_are_enough(monkeypatch, tmp_path):
    monkeypatch.setattr(__import__(__name__, fromlist=["SHARED"]), "SHARED", tmp_path / "absent")
    load.cache_clear()
    try:
        for name in FILES:
            assert load(name) == json.loads((FIXTURES / Path(FILES[name]).name).read_text())
    finally:
        load.cache_clear()
