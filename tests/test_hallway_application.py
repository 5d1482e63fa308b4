"""The hallway application end to end, in simulated time, through the real protocol code."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hapticop.cli import app
from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus

from .conftest import CORPUS, SYSTEMS
from .runtime_helpers import compose


@pytest.fixture(scope="module")
def hallway_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hallway")
    result = compose(tmp, (SYSTEMS / "hallway.yaml").read_text(), duration=None, name="hallway", seed=0)
    return result, tmp / "run-hallway"


@pytest.mark.timeout(360)  # the module's hallway run happens here: a bound on hangs on a busy machine, not a speed
def test_the_run_finishes_by_itself_and_meets_the_targets(hallway_run):
    result, run = hallway_run
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["ended_by"] == "stopped" and not metrics["crash"] and metrics["n_collisions"] == 0
    assert -0.05 <= metrics["e_stop_m"] <= 0.10  # docs/hallway-experiment.md §6, braking field
    results = json.loads((run / "results.json").read_text())
    assert all(row["ok"] is not False for row in results["rows"])
    assert (run / "run.png").read_bytes()[:4] == b"\x89PNG"


def test_the_stop_is_calm_and_the_robot_holds_still(hallway_run):
    """Issue 18: the cue near the stop no longer pumps the hand for seconds, the stopped robot does not
    drift back, and the completion time is judged against the autonomous reference."""
    _, run = hallway_run
    metrics = json.loads((run / "metrics.json").read_text())
    # §5: the 2 s index above 2 cm/s for more than 2 s is sustained; here only the first push lifts it
    assert not metrics["sustained_oscillation"] and metrics["oscillation_s"] < 1.0
    assert not metrics["divergence"]
    assert metrics["hold_speed_mps"] <= 0.005  # was 0.014 m/s, up to 0.028 m/s backwards
    trajectory = np.load(run / "trajectory.npz")
    assert trajectory["robot_velocity"][-1, 0] > -0.002  # not reversing at the end either
    assert metrics["t_ref_s"] > 0 and metrics["t_norm"] <= 1.2
    rows = json.loads((run / "results.json").read_text())["rows"]
    named = {row["metric"].split(" (")[0]: row for row in rows}
    for metric in ("oscillation index", "divergence", "rms force rate", "completion time / T_ref",
                   "drift while stopped"):
        assert metric in named  # every metric the run computes is in the table


@pytest.mark.timeout(360)  # a whole hallway run: a bound on hangs on a busy machine, not a speed
def test_check_fails_a_run_that_misses_a_target(tmp_path):
    """`compose --check` turns a missed target into exit status 1: without the ropod's standstill hold the
    stopped robot drifts back (the run itself succeeds, exit 0 without --check)."""
    hold = "      hold_below: 0.02"
    text = (SYSTEMS / "hallway.yaml").read_text()
    assert hold in text
    text = text.replace(hold, "      # " + hold.strip())
    path = tmp_path / "early.yaml"
    path.write_text(text)
    result = runner.invoke(app, ["compose", str(path), "--clock", "virtual", "--check",
                                 "--run-dir", str(tmp_path / "run"), "--control", str(tmp_path / "ctl")])
    assert result.exit_code == 1, result.output
    assert "target missed" in result.output and "drift while stopped" in result.output
    rows = json.loads((tmp_path / "run" / "results.json").read_text())["rows"]
    assert any(row["ok"] is False for row in rows)


def test_every_device_went_through_its_protocol(hallway_run):
    _, run = hallway_run
    assert "homed after" in (run / "falcon.log").read_text()  # 16-byte frames, homing bit, FK
    assert "LIDAR streaming" in (run / "lidar.log").read_text()  # CoLa A start-up over loopback TCP
    assert "all 7 slaves operational" in (run / "ethercat_watchdog.log").read_text()  # PDO images, AL states
    trajectory = np.load(run / "trajectory.npz")
    assert trajectory["pose"][-1, 0] > 8.0  # the robot really drove down the 10 m hallway
    assert np.abs(trajectory["force_env"]).max() > 0.5  # and the operator felt the end wall coming


def test_same_seed_same_run(tmp_path):
    text = (SYSTEMS / "hallway.yaml").read_text().replace("time_limit_s: 90.0", "time_limit_s: 4.0")
    a = compose(tmp_path, text, duration=None, name="a", seed=5)
    b = compose(tmp_path, text, duration=None, name="b", seed=5)
    assert a.outcome.status is ExitStatus.SUCCESS and b.outcome.status is ExitStatus.SUCCESS
    pa, pb = (np.load(tmp_path / f"run-{n}" / "trajectory.npz")["pose"] for n in "ab")
    assert pa.shape == pb.shape and pa.tobytes() == pb.tobytes()


def test_desk_renders_the_surroundings_without_moving_the_robot(tmp_path):
    text = (SYSTEMS / "desk.yaml").read_text().replace("time_limit_s: 20.0", "time_limit_s: 5.0")
    result = compose(tmp_path, text, duration=None, name="desk")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    trajectory = np.load(tmp_path / "run-desk" / "trajectory.npz")
    assert np.ptp(trajectory["pose"], axis=0).max() == 0.0  # the robot's threads stayed on schedule 0
    assert np.abs(trajectory["force_env"]).max() > 0.1  # yet the walls are felt
    assert result.states["ropod"] is State.DONE
    assert "-> running" not in (tmp_path / "run-desk" / "ropod.log").read_text()  # only cleaned at the end
    assert not (tmp_path / "run-desk" / "results.json").exists()  # not a hallway run: nothing judged


runner = CliRunner()


def test_lidar_decode_cli():
    capture = CORPUS.parent / "fixtures" / "sick" / "cola_a" / "tim561_sRA_LMDscandata_sim00.bin"
    result = runner.invoke(app, ["lidar", "decode", str(capture), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert len(data["ranges_m"]) == 811 and data["ranges_m"][0] == pytest.approx(1.598)
    garbage = runner.invoke(app, ["lidar", "decode", str(CORPUS / "invalid" / "invalid-empty-file.yaml")])
    assert garbage.exit_code == 1 and "not a scan telegram" in garbage.output


def test_falcon_ik_fk_cli_round_trip():
    ik = runner.invoke(app, ["falcon", "ik", "0.01", "-0.02", "0.13", "--json"])
    counts = json.loads(ik.output)["counts"]
    fk = runner.invoke(app, ["falcon", "fk", *map(str, counts), "--json"])
    assert fk.exit_code == 0, fk.output
    assert json.loads(fk.output)["position_m"] == pytest.approx([0.01, -0.02, 0.13], abs=2e-4)  # one count
    assert runner.invoke(app, ["falcon", "ik", "1", "1", "1"]).exit_code == 1


def test_the_readme_command_runs_the_hallway_in_real_time(tmp_path):
    """`hapticop compose systems/hallway.yaml` on the wall clock, fieldbus in its own process."""
    import subprocess
    import sys

    from .conftest import ROOT

    run = tmp_path / "run"
    result = subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", "systems/hallway.yaml",
                             "--run-dir", str(run)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "hallway H1, nominal operator" in result.stderr and "Traceback" not in result.stderr
    metrics = json.loads((run / "metrics.json").read_text())
    # the nominal operator stops before the end wall on the wall clock as in simulated time: a crash or a
    # run that timed out is a failure of the real-time system, not an acceptable ending
    assert metrics["ended_by"] == "stopped" and not metrics["crash"] and metrics["n_collisions"] == 0, metrics
    assert "runs in process" in (run / "system.log").read_text()
