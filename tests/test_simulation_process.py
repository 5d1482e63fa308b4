"""The simulation can leave the 1 kHz loop's process: the simulated Falcon, the blind operator and the
world on a thread of their own, in a process of their own without real-time priority, reached by the
Falcon's frames and by streams (tests/fixtures/simulation_process.yaml)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus

from .conftest import FIXTURES
from .runtime_helpers import compose

TEXT = (FIXTURES / "simulation_process.yaml").read_text()


@pytest.mark.parametrize("clock", ["virtual", "realtime"])
def test_the_operator_homes_and_drives_a_falcon_simulated_in_another_process(tmp_path, clock):
    result = compose(tmp_path, TEXT, clock=clock, duration="60s", name="sim")  # it ends by itself, long before
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    run = tmp_path / "run-sim"
    assert "homed after" in (run / "falcon.log").read_text()  # frames both ways, homing bits, the LED seen
    assert "the operator starts driving" in (run / "operator.log").read_text()
    assert "run judged over" in (run / "world.log").read_text()  # the world judged, and the net stopped the run
    results = json.loads((run / "results.json").read_text())
    assert results["title"] == "hallway H1, nominal operator"
    # one end time: the log, the results table and the metrics' completion time tell the same one
    [logged] = re.findall(r"run ended at ([0-9.]+) s after the operator started", (run / "world.log").read_text())
    [row] = [r for r in results["rows"] if r["metric"].startswith("run ended at")]
    metrics = json.loads((run / "metrics.json").read_text())
    assert float(logged) == pytest.approx(row["value"], abs=1e-3)
    if metrics["ended_by"] == "stopped":
        assert row["value"] == pytest.approx(metrics["completion_time_s"], abs=1e-3)
    else:  # it ended without stopping: the end is the last moment recorded
        assert row["value"] == pytest.approx(trajectory_seconds(run), abs=1e-3)
    trajectory = np.load(run / "trajectory.npz")
    assert trajectory["handle_position"][:, 2].min() < -0.01  # the operator pushed the grip forward
    assert np.abs(trajectory["force_device"]).max() > 0.1  # against the spring the Falcon rendered
    if clock == "realtime":
        assert "thread 'simulation' runs in process" in (run / "system.log").read_text()


def trajectory_seconds(run) -> float:
    t = np.load(run / "trajectory.npz")["t"]
    return float(t[-1] - t[0])


def test_under_the_virtual_clock_a_rerun_is_identical(tmp_path):
    for name in ("a", "b"):
        assert compose(tmp_path, TEXT, duration="60s", name=name, seed=3).outcome.status is ExitStatus.SUCCESS
    a, b = (np.load(tmp_path / f"run-{name}" / "trajectory.npz") for name in ("a", "b"))
    assert a["handle_position"].shape == b["handle_position"].shape
    assert a["handle_position"].tobytes() == b["handle_position"].tobytes()
    assert a["force_hand"].tobytes() == b["force_hand"].tobytes()
