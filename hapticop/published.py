"""What an activity tells the other activities of its run through the run directory.

A simulator says where it serves its device, a world what its walls are, an operator who it is:
facts fixed for a run that a reader in any process of the run may need. Each is written whole
(a reader never sees half of it) with its writer's process id, so a fact left in a reused run
directory by a process that has ended is not taken for this run's.

A fact is data, never code: it is written as JSON (a dataclass as its fields, a tuple as a list,
an array as its elements) and read back as plain data, or as the type the reader names
(`as_type`, checked by pydantic). Whoever can write into a run directory can then plant wrong
facts, but not make a reader run anything; a file that is not such a fact is no answer (None).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import TypeAdapter, ValidationError
from pydantic_core import to_jsonable_python

MAX_BYTES = 1 << 20  # a fact is small (a world's walls): a larger file is none


def _file(run_dir: Path, kind: str, activity: str) -> Path:
    return Path(run_dir) / kind / f"{activity}.json"


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a fact (data: numbers, text, lists, dicts, dataclasses, arrays)")


def publish(run_dir: Path, kind: str, activity: str, value: Any) -> None:
    """Say `value` as `activity`'s `kind` ("links", "worlds", ...) for this run."""
    path = _file(run_dir, kind, activity)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps({"pid": os.getpid(), "value": to_jsonable_python(value, fallback=_plain)})
    temporary = path.with_suffix(f".{os.getpid()}.tmp")
    temporary.write_text(text)
    temporary.replace(path)


def published(run_dir: Path, kind: str, activity: str, *, as_type: Any = None,
              while_writer_lives: bool = True) -> Any | None:
    """What `activity` said as its `kind` (as `as_type` when given), or None until it has (or, by
    default, once its writer has ended: in a reused run directory that may be another run's), and
    None for a file that is no fact (not a regular file, not JSON, no writer's process id, not an
    `as_type`)."""
    fact = _read(_file(run_dir, kind, activity))
    if fact is None or (while_writer_lives and not _alive(fact[0])):
        return None
    if as_type is None:
        return fact[1]
    try:
        return TypeAdapter(as_type).validate_python(fact[1])
    except ValidationError:
        return None


def _read(path: Path) -> tuple[int, Any] | None:
    """The writer's process id and the value of the fact at `path`, or None."""
    try:
        # not blocking: a FIFO planted in place of a fact must not hang its reader
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(descriptor).st_mode):
            return None
        data = os.read(descriptor, MAX_BYTES + 1)
    except OSError:
        return None
    finally:
        os.close(descriptor)
    try:
        fact = json.loads(data) if len(data) <= MAX_BYTES else None
    except (ValueError, RecursionError):  # not UTF-8, not JSON, nested beyond reason
        return None
    if not isinstance(fact, dict) or set(fact) != {"pid", "value"}:
        return None
    pid = fact["pid"]
    if type(pid) is not int or pid <= 0:  # 0 or -1 would ask about a whole group of processes
        return None
    return pid, fact["value"]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except PermissionError:  # alive, another user's
        return True
    except (ProcessLookupError, OverflowError):
        return False
    return True


def withdraw(run_dir: Path, kind: str, activity: str) -> None:
    _file(run_dir, kind, activity).unlink(missing_ok=True)
