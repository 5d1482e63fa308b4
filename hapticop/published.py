"""What an activity tells the other activities of its run through the run directory.

A simulator says where it serves its device, a world what its walls are, an operator who it is:
facts fixed for a run that a reader in any process of the run may need. Each is written whole
(a reader never sees half of it) with its writer's process id, so a fact left in a reused run
directory by a process that has ended is not taken for this run's.
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any


def _file(run_dir: Path, kind: str, activity: str) -> Path:
    return Path(run_dir) / kind / f"{activity}.pickle"


def publish(run_dir: Path, kind: str, activity: str, value: Any) -> None:
    """Say `value` as `activity`'s `kind` ("links", "worlds", ...) for this run."""
    path = _file(run_dir, kind, activity)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(f".{os.getpid()}.tmp")
    temporary.write_bytes(pickle.dumps((os.getpid(), value)))
    temporary.replace(path)


def published(run_dir: Path, kind: str, activity: str, *, while_writer_lives: bool = True) -> Any | None:
    """What `activity` said as its `kind`, or None until it has (or, by default, once its writer
    has ended: in a reused run directory that may be another run's)."""
    try:
        pid, value = pickle.loads(_file(run_dir, kind, activity).read_bytes())
        if while_writer_lives:
            os.kill(pid, 0)
    except (FileNotFoundError, ProcessLookupError, EOFError, ValueError, pickle.UnpicklingError):
        return None
    except PermissionError:  # alive, another user's
        pass
    return value


def withdraw(run_dir: Path, kind: str, activity: str) -> None:
    _file(run_dir, kind, activity).unlink(missing_ok=True)
