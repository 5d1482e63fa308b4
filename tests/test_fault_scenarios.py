"""Device faults while driving (systems/faults.yaml, virtual clock): each stops the robot, each recovers.

The checks read the world's recording: when the velocity setpoint went to zero after a fault,
whether the robot came to rest before the fault cleared, and whether the operator moved it
again after. Simulated time, so these are the logic's reaction times, exactly.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hapticop.runtime.system import ExitStatus
from hapticop.sim.faults import fault_windows, reactions

from .conftest import SYSTEMS
from .runtime_helpers import compose

# The shared setup runs every fault scenario of the hallway under the virtual clock (about a minute
# on two idle cores): more than pytest's per-test bound when the machine is busy, never a hang.
pytestmark = pytest.mark.timeout(360)


@pytest.fixture(scope="module")
def faults_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("faults")
    (tmp / "hallway.yaml").write_text((SYSTEMS / "hallway.yaml").read_text())  # what faults.yaml extends
    result = compose(tmp, (SYSTEMS / "faults.yaml").read_text(), duration=None, name="faults", seed=0)
    run = tmp / "run-faults"
    recording = np.load(run / "trajectory.npz")
    meta = json.loads(str(recording["__meta__"]))
    from hapticop.validation import validate_path

    windows = fault_windows(validate_path(tmp / "faults.yaml").composition)
    found = {(r.window.activity, r.window.fault): r for r in reactions(
        recording["t"], recording["cmd"], recording["robot_velocity"], meta["operator_start_ns"],
        result.timing["started_ns"], windows)}
    return result, run, found


def test_every_scripted_fault_is_found(faults_run):
    _, _, found = faults_run
    assert set(found) == {("falcon_sim", "silent"), ("falcon_sim", "corrupt"), ("lidar_sim", "stall"),
                          ("lidar_sim", "unplugged"), ("lidar_sim", "garbage")}


@pytest.mark.parametrize("fault", ["silent", "corrupt"])
def test_lost_falcon_frames_stop_the_robot_within_100_ms_and_driving_resumes(faults_run, fault):
    _, _, found = faults_run
    reaction = found[("falcon_sim", fault)]
    assert reaction.to_zero_setpoint_s <= 0.100  # the firmware itself holds a force only 100 ms
    assert reaction.to_rest_s < 1.0  # at rest before the fault clears (1 s window)
    assert reaction.resumed_after_s < 0.5


@pytest.mark.parametrize("fault", ["stall", "unplugged"])
def test_a_blind_robot_stops_and_drives_again_once_scans_return(faults_run, fault):
    _, _, found = faults_run
    reaction = found[("lidar_sim", fault)]
    assert reaction.to_zero_setpoint_s <= 0.200 + 1 / 15  # stale after three periods from the last scan
    assert reaction.to_rest_s < 1.0
    assert reaction.resumed_after_s < 2.5  # reconnection backoff at most 2 s


def test_garbage_is_skipped_without_stopping(faults_run):
    _, run, found = faults_run
    assert math.isnan(found[("lidar_sim", "garbage")].to_zero_setpoint_s)  # resynchronised: the scan stayed fresh
    during = [line for line in (run / "haptic.log").read_text().splitlines() if 18.0 <= float(line.split()[0]) < 19.5]
    assert not any("scan stale" in line for line in during)


def test_the_run_still_ends_at_the_wall(faults_run):
    result, run, _ = faults_run
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["ended_by"] == "stopped" and not metrics["crash"] and metrics["n_collisions"] == 0
    log = (run / "falcon.log").read_text() + (run / "haptic.log").read_text() + (run / "lidar.log").read_text()
    # a running parameter: no reconfiguration, no re-homing
    for activity in ("falcon_sim", "falcon", "lidar", "lidar_sim"):
        assert (run / f"{activity}.log").read_text().count("-> running") == 1
    for said in ("no good frame for 100 ms", "frames are back", "handle position stale", "driving resumes",
                 "scan stale: blind", "scan fresh again", "stream stalled"):
        assert said in log
