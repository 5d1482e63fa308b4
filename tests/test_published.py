"""A run's published facts are data: whatever is planted in the run directory is refused, never run."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import pytest

from hapticop.published import MAX_BYTES, publish, published, withdraw


@dataclass(frozen=True)
class Wall:
    name: str
    corners: tuple[tuple[float, float], ...]


class Planted:
    """Unpickling this runs a command that leaves a file: the proof a reader executed the fact."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_a_fact_is_read_back_as_data_or_as_the_type_asked_for(tmp_path):
    publish(tmp_path, "worlds", "w", Wall("end", ((0.0, 1.0), (2.0, 3.0))))
    assert published(tmp_path, "worlds", "w") == {"name": "end", "corners": [[0.0, 1.0], [2.0, 3.0]]}
    assert published(tmp_path, "worlds", "w", as_type=Wall) == Wall("end", ((0.0, 1.0), (2.0, 3.0)))
    assert published(tmp_path, "worlds", "w", as_type=tuple[str, int]) is None  # not what was asked for
    publish(tmp_path, "links", "sim", ("127.0.0.1", 40123))
    assert published(tmp_path, "links", "sim", as_type=tuple[str, int]) == ("127.0.0.1", 40123)
    publish(tmp_path, "operators", "op", {"gains": np.array([1.5, 2.0]), "seed": np.int64(3)})
    assert published(tmp_path, "operators", "op") == {"gains": [1.5, 2.0], "seed": 3}
    with pytest.raises(TypeError, match="not a fact"):
        publish(tmp_path, "operators", "op", {"code": Planted(tmp_path / "never")})
    code = pickle.dumps(Planted(tmp_path / "executed")).decode("latin-1")
    publish(tmp_path, "operators", "op", {"code": code})  # a pickle inside a fact is text, and stays text
    assert published(tmp_path, "operators", "op") == {"code": code} and not (tmp_path / "executed").exists()
    withdraw(tmp_path, "operators", "op")
    assert published(tmp_path, "operators", "op") is None


PLANTED = {
    "a pickle": lambda marker: pickle.dumps((os.getpid(), Planted(marker))),
    "garbage": lambda marker: os.urandom(512),
    "not UTF-8": lambda marker: b'{"pid": 1, "value": "\xff"}',
    "JSON, not a fact": lambda marker: json.dumps([os.getpid(), "value"]).encode(),
    "a fact with more fields": lambda marker: json.dumps({"pid": os.getpid(), "value": 1, "code": "x"}).encode(),
    "a process group for a writer": lambda marker: json.dumps({"pid": 0, "value": 1}).encode(),
    "every process for a writer": lambda marker: json.dumps({"pid": -1, "value": 1}).encode(),
    "a writer that is no number": lambda marker: json.dumps({"pid": True, "value": 1}).encode(),
    "a writer beyond any pid": lambda marker: json.dumps({"pid": 1 << 70, "value": 1}).encode(),
    "nested beyond reason": lambda marker: b'{"pid": %d, "value": ' % os.getpid() + b"[" * 100_000 + b"]" * 100_000
    + b"}",
    "too large": lambda marker: json.dumps({"pid": os.getpid(), "value": "x" * MAX_BYTES}).encode(),
}


@pytest.mark.parametrize("kind", list(PLANTED))
def test_a_planted_file_is_no_fact_and_runs_nothing(tmp_path, kind):
    """Read in a child process, as a reader of the run would: it prints None, says nothing on its
    error stream and runs nothing (the planted pickle would leave the marker file)."""
    marker = tmp_path / "executed"
    folder = tmp_path / "run" / "worlds"
    folder.mkdir(parents=True)
    for name in ("world.json", "world.pickle"):  # where facts are, and where they were
        (folder / name).write_bytes(PLANTED[kind](marker))
    read = subprocess.run([sys.executable, "-c", "import sys; from hapticop.published import published; "
                           "print(published(sys.argv[1], 'worlds', 'world'))", str(tmp_path / "run")],
                          capture_output=True, text=True, timeout=60)
    assert (read.returncode, read.stdout, read.stderr) == (0, "None\n", "")
    assert not marker.exists()


def test_a_fifo_or_a_directory_in_place_of_a_fact_is_none_and_hangs_nothing(tmp_path):
    (tmp_path / "worlds").mkdir()
    os.mkfifo(tmp_path / "worlds" / "world.json")  # nobody writes it: a blocking open would wait for ever
    (tmp_path / "worlds" / "other.json").mkdir()
    read = subprocess.run([sys.executable, "-c", "import sys; from hapticop.published import published; "
                           "print(published(sys.argv[1], 'worlds', 'world'), "
                           "published(sys.argv[1], 'worlds', 'other'))",
                           str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert (read.stdout, read.stderr) == ("None None\n", "")
