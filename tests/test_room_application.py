"""systems/room.yaml: the hallway's driving application in a room of the user's own (a scene file beside it),
under the virtual clock, judged from the run's own metrics.json and trajectory."""

import json

import numpy as np
import pytest

from hapticop.runtime.system import ExitStatus
from hapticop.validation import validate_path

from .conftest import SYSTEMS
from .runtime_helpers import compose


@pytest.mark.timeout(360)  # a whole run through the doorway: a bound on hangs on a busy machine, not a speed
def test_the_operator_drives_through_the_doorway_past_the_pillar_to_a_stop_without_collision(tmp_path):
    (tmp_path / "hallway.yaml").write_text((SYSTEMS / "hallway.yaml").read_text())  # what room.yaml extends
    (tmp_path / "scenes").mkdir()
    scene = (SYSTEMS / "scenes" / "room.yaml").read_text()
    (tmp_path / "scenes" / "room.yaml").write_text(scene)  # the scene beside it
    result = compose(tmp_path, (SYSTEMS / "room.yaml").read_text(), duration=None, name="room", seed=0)
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    run = tmp_path / "run-room"
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["ended_by"] == "stopped"  # the operator stopped by itself, not the time limit nor a crash
    assert not metrics["crash"] and metrics["n_collisions"] == 0
    assert metrics["clearance_min_m"] > 0.1  # MuJoCo's distance to the nearest wall, doorway or pillar
    assert -0.05 <= metrics["e_stop_m"] <= 0.10  # 0.5 m before the room's end wall, as in the hallway
    pose = np.load(run / "trajectory.npz")["pose"]
    assert pose[:, 0].max() > 5.5  # through the doorway at x = 3 m and past the pillar at x = 5.5 m
    assert np.abs(pose[pose[:, 0] < 3.5, 1]).max() < 0.5  # through the doorway, not around it


def test_the_room_is_found_beside_the_composition():
    assert validate_path(SYSTEMS / "room.yaml").report.diagnostics == []
