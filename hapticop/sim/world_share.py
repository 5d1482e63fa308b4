"""What a simulated world shares with the simulators that live in it, found by its activity's name.

The world's geometry (walls, pillars, the LIDAR's noise) is fixed for a run, so the world writes it
once into the run directory, where a simulator in any process of the run finds it by the world
activity's name (the name its `world:` parameter gives, which validation checks). Everything that
moves (the robot's pose, the operator's hand) travels in declared streams instead. The same way,
the operator says who it is (its variant), which the world's judge needs for the run's targets.
"""

from __future__ import annotations

import json
import os
import pickle
from pathlib import Path

from hapticop.sim.hallway import HallwayGeometry


def _file(run_dir: Path, activity: str) -> Path:
    return Path(run_dir) / "worlds" / f"{activity}.pickle"


def publish_world(run_dir: Path, activity: str, geometry: HallwayGeometry) -> None:
    """Write the world's geometry where its simulators look (whole: a reader never sees half)."""
    path = _file(run_dir, activity)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(f".{os.getpid()}.tmp")
    temporary.write_bytes(pickle.dumps((os.getpid(), geometry)))
    temporary.replace(path)


def find_world(run_dir: Path, activity: str) -> HallwayGeometry | None:
    """The geometry of the world `activity`, or None until it is open (a world left behind by an
    ended run in a reused run directory does not count)."""
    try:
        pid, geometry = pickle.loads(_file(run_dir, activity).read_bytes())
        os.kill(pid, 0)
    except (FileNotFoundError, ProcessLookupError, EOFError, pickle.UnpicklingError):
        return None
    except PermissionError:
        pass
    return geometry


def withdraw_world(run_dir: Path, activity: str) -> None:
    _file(run_dir, activity).unlink(missing_ok=True)


def _operator_file(run_dir: Path, activity: str) -> Path:
    return Path(run_dir) / "operators" / f"{activity}.json"


def publish_operator(run_dir: Path, activity: str, description: dict) -> None:
    """Say who the operator `activity` is (its variant, its seed), written whole."""
    path = _operator_file(run_dir, activity)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(f".{os.getpid()}.tmp")
    temporary.write_text(json.dumps(description))
    temporary.replace(path)


def find_operator(run_dir: Path, activity: str) -> dict | None:
    """What the operator `activity` said about itself this run, or None if it said nothing."""
    try:
        return json.loads(_operator_file(run_dir, activity).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
