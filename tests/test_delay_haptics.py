"""Haptics that do not depend on the delay: the energy tank, the commands' dead reckoning, and the blocks
that put them and the emulated link into a composition (docs/teleop.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hapticop.haptics.energy_tank import EnergyTank, EnergyTankParams
from hapticop.haptics.force_models import BrakingField
from hapticop.haptics.prediction import CommandOdometry, PredictionParams, arc
from hapticop.testing import BlockHarness

# -- the energy tank ----------------------------------------------------------------------------------------------

finite = st.floats(-20.0, 20.0, allow_nan=False)
vectors = st.tuples(finite, finite, finite)
speeds = st.tuples(*(st.floats(-1.0, 1.0, allow_nan=False),) * 3)


@st.composite
def tanks(draw):
    low = draw(st.floats(0.0, 0.2))
    high = low + draw(st.floats(0.01, 0.5))
    start = draw(st.floats(low, high))
    return EnergyTankParams(initial_j=start, max_j=high, min_j=low,
                            refill_damping_ns_per_m=draw(st.floats(0.0, 2.0)), period_s=0.001)


@settings(max_examples=60, deadline=None)
@given(params=tanks(), steps=st.lists(st.tuples(vectors, speeds), min_size=1, max_size=300))
def test_the_tank_never_runs_below_its_floor_and_bounds_the_energy_given_over_any_window(params, steps):
    tank = EnergyTank(params)
    out = np.zeros(3)
    given_j, refill_j, levels = [0.0], [0.0], [tank.level_j]
    for force, velocity in steps:
        f, v = np.array(force), np.array(velocity)
        tank.step(f, v, out)
        assert params.min_j <= tank.level_j <= params.max_j
        assert np.all(np.abs(out) <= np.abs(f) + 1e-12)  # only ever scaled down, never turned round
        given_j.append(given_j[-1] + float(out @ v) * params.period_s)
        refill_j.append(refill_j[-1] + params.refill_damping_ns_per_m * float(v @ v) * params.period_s)
        levels.append(tank.level_j)
    assert tank.lowest_j == pytest.approx(min(levels))
    given_j, refill_j = np.array(given_j), np.array(refill_j)
    budget = params.max_j - params.min_j
    for a in range(len(given_j)):  # every window [a, b]: what the force gave is bounded
        window_given = given_j[a:] - given_j[a]
        window_refill = refill_j[a:] - refill_j[a]
        assert np.all(window_given <= budget + window_refill + 1e-9)


def test_a_full_tank_passes_the_force_untouched_and_an_empty_one_holds_it_back():
    tank = EnergyTank(EnergyTankParams(initial_j=0.01, max_j=0.3, min_j=0.0, refill_damping_ns_per_m=0.0))
    out = np.zeros(3)
    force, velocity = np.array([0.0, 0.0, 5.0]), np.array([0.0, 0.0, 0.1])  # 0.5 W given to the hand
    assert tank.step(force, velocity, out) == 1.0 and out[2] == 5.0
    for _ in range(19):
        tank.step(force, velocity, out)
    assert tank.level_j == pytest.approx(0.0, abs=1e-12)  # 20 ms at 0.5 W spent the 10 mJ
    assert tank.step(force, velocity, out) == 0.0 and out[2] == 0.0
    tank.step(force, -velocity, out)  # the hand pushing back into the cue fills the tank again
    assert out[2] == 5.0 and tank.level_j == pytest.approx(0.5e-3)


def test_the_tank_is_refilled_by_the_dampers_dissipation_up_to_its_capacity():
    tank = EnergyTank(EnergyTankParams(initial_j=0.0, max_j=0.3, refill_damping_ns_per_m=2.0))
    out = np.zeros(3)
    tank.step(np.zeros(3), np.array([0.1, 0.0, 0.0]), out)
    assert tank.level_j == pytest.approx(2.0 * 0.01 * 0.001)
    for _ in range(100_000):
        tank.step(np.zeros(3), np.array([1.0, 0.0, 0.0]), out)
    assert tank.level_j == 0.3


def test_the_tank_refuses_a_start_outside_its_bounds():
    with pytest.raises(ValueError, match="min_j <= initial_j <= max_j"):
        EnergyTankParams(initial_j=0.5, max_j=0.3)


# -- the commands' dead reckoning -----------------------------------------------------------------------------------

def odometry_fed(twist, seconds: float, period: float = 0.001) -> CommandOdometry:
    odometry = CommandOdometry(PredictionParams(history_s=seconds + 1.0, period_s=period))
    for k in range(int(round(seconds / period)) + 1):
        odometry.command(k * period, np.array(twist))
    return odometry


@settings(max_examples=40, deadline=None)
@given(vx=st.floats(-1.0, 1.0), vy=st.floats(-0.5, 0.5), wz=st.floats(-1.5, 1.5),
       since=st.floats(0.0, 1.0), span=st.floats(0.0, 1.0))
def test_a_constant_command_is_predicted_exactly(vx, vy, wz, since, span):
    odometry = odometry_fed((vx, vy, wz), 2.0)
    travel = odometry.travel(since, since + span, np.zeros(3))
    # closed form: the body holds the twist, so its motion in its own starting frame is the arc
    assert travel == pytest.approx(arc(vx, vy, wz, span), abs=1e-9)
    if abs(wz) > 1e-3:
        assert travel[0] == pytest.approx((vx * math.sin(wz * span) + vy * (math.cos(wz * span) - 1)) / wz, abs=1e-9)


def test_commands_that_change_are_integrated_piece_by_piece():
    odometry = CommandOdometry(PredictionParams(history_s=5.0))
    odometry.command(0.0, np.array([0.5, 0.0, 0.0]))
    odometry.command(1.0, np.array([0.0, 0.0, math.pi / 2]))  # a quarter turn on the spot
    odometry.command(2.0, np.array([0.5, 0.0, 0.0]))  # then ahead again, now along +y
    assert odometry.travel(0.0, 3.0, np.zeros(3)) == pytest.approx([0.5, 0.5, math.pi / 2], abs=1e-12)
    assert odometry.travel(0.5, 2.5, np.zeros(3)) == pytest.approx([0.25, 0.25, math.pi / 2], abs=1e-12)
    # seen from the robot's frame after the turn: it went ahead 0.5 m, from where it was 0.5 m behind
    assert odometry.travel(2.0, 3.0, np.zeros(3)) == pytest.approx([0.5, 0.0, 0.0], abs=1e-12)


def test_a_time_beyond_the_memory_is_predicted_from_the_oldest_command():
    odometry = odometry_fed((1.0, 0.0, 0.0), 3.0, period=0.01)  # 1 s of history plus 3 s fed: 4 s kept, hardly
    travel = odometry.travel(-10.0, 3.0, np.zeros(3))
    assert 0.0 < travel[0] <= 3.0


def test_the_braking_field_renders_the_predicted_travel_as_its_own_twist_times_age():
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 811)
    ranges = np.full(811, np.nan)
    ahead = np.abs(angles) < 0.5
    ranges[ahead] = 1.4 / np.cos(angles[ahead])  # a wall 1.4 m ahead of the scanner
    handle, twist = np.array([0.0, 0.0, -0.02]), np.array([0.5, 0.0, 0.0])
    by_age, by_travel = BrakingField(), BrakingField()
    for field in (by_age, by_travel):
        field.configure(angles)
        field.update_scan(ranges)
    a, b = np.zeros(3), np.zeros(3)
    for _ in range(500):  # the risk's rate limit settles
        by_age.render(handle, twist, a, scan_age_s=0.4)
        by_travel.render(handle, twist, b, scan_age_s=99.0, travel=np.array([0.2, 0.0, 0.0]))
    assert by_age.gap_m == pytest.approx(by_travel.gap_m) and a == pytest.approx(b)
    assert abs(b[2]) > 0.5  # a cue is felt


# -- the blocks -----------------------------------------------------------------------------------------------------

def test_the_link_block_delivers_after_its_delay_keeps_the_newest_and_says_how_long_it_took():
    harness = BlockHarness("link", {"streams": {"command": {"shape": [3]}},
                                    "link": {"delay_s": 0.05, "jitter_s": 0.01, "reorder": True, "seed": 4}})
    harness.configure()
    received, delays, sent_at = [], [], {}
    for k in range(400):
        if k < 300:
            harness.feed("command", [k, 0.0, 0.0])
            sent_at[k] = harness.clock.now_ns()
        harness.step()
        out = harness.outputs.command_received
        if out.published > len(received):
            received.append(int(out.value[0]))
            delays.append(float(harness.outputs.command_delay.value))
    assert received == sorted(received)  # a reordered, older sample is dropped: the newest is held
    assert len(received) < 300 and received[-1] == 299
    assert all(0.04 - 1e-9 <= d <= 0.06 + 1e-9 for d in delays)
    harness.clean()
    assert any("late dropped" in line and " 0 late dropped" not in line for line in harness.log_lines())


def test_the_link_block_runs_the_same_twice_and_its_streams_have_their_own_luck():
    def arrivals(seed: int) -> tuple[list[int], list[int]]:
        harness = BlockHarness("link", {"streams": {"a": {}, "b": {}}, "link": {"delay_s": 0.01, "loss": 0.3,
                                                                                   "seed": seed}})
        harness.configure()
        got: tuple[list[int], list[int]] = ([], [])
        for k in range(300):
            harness.feed("a", float(k))
            harness.feed("b", float(k))
            harness.step()
            for lane, port in zip(got, (harness.outputs.a_received, harness.outputs.b_received)):
                if port.published > len(lane):
                    lane.append(int(port.value))
        return got

    first = arrivals(7)
    assert first == arrivals(7)
    assert first[0] != first[1]
    assert first != arrivals(8)


def test_the_round_trip_block_measures_the_echoes_of_its_pings(tmp_path):
    """Each ping [slot, send time] comes back 120 ms later but every fifth, lost. The round trip is the
    echoes', the loss the fraction never echoed, and nothing is said before the first echo."""
    harness = BlockHarness("round_trip", {"ping_period_s": 0.05}, name="pinger", run_dir=tmp_path)
    harness.configure()
    in_flight: list[tuple[int, np.ndarray]] = []
    pings = 0
    for k in range(3000):
        now = harness.clock.now_ns()
        while in_flight and in_flight[0][0] <= now:
            harness.feed("echo", in_flight.pop(0)[1])
        harness.step()
        ping = harness.outputs.ping
        if ping.published > pings:
            pings = ping.published
            if pings % 5:
                in_flight.append((now + 120_000_000, ping.value.copy()))
        if k == 50:
            assert harness.outputs.rtt.published == 0  # nothing answered yet: nothing said
    assert float(harness.outputs.rtt.value) == pytest.approx(0.120, abs=0.0015)
    assert float(harness.outputs.loss.value) == pytest.approx(0.2, abs=0.05)
    assert float(harness.outputs.jitter.value) < 0.002
    harness.clean()
    assert any("round trip 120" in line or "round trip 121" in line for line in harness.log_lines())
    rows = {row["metric"]: row["value"] for row in json.loads(
        (tmp_path / "results-link-pinger.json").read_text())["rows"]}
    assert rows["round trip max"] == pytest.approx(120, abs=1.5) and rows["pings unanswered"] > 0.1


def test_the_predictor_dead_reckons_from_the_scans_time_less_the_forward_delay():
    harness = BlockHarness("pose_predictor", {"prediction": {"forward_delay_s": 0.1}})
    harness.configure()
    for k in range(1000):  # 1 s of 0.5 m/s ahead
        harness.feed("command", [0.5, 0.0, 0.0])
        if k == 800:
            harness.feed("model_delay", 0.3)  # a scan arrives at 0.8 s, taken at 0.5 s
        harness.step()
    # the robot moved from where it was at 0.5 s − 0.1 s to where it is when the command sent now (0.999 s) lands
    assert harness.outputs.travel.value == pytest.approx([0.5 * (0.999 - 0.4), 0.0, 0.0], abs=1e-3)
    harness.feed("round_trip", 0.6)  # a measured round trip wins over the parameter: 0.3 s forward
    harness.feed("command", [0.5, 0.0, 0.0])
    harness.step()
    assert harness.outputs.travel.value[0] == pytest.approx(0.5 * (1.0 - 0.2), abs=1e-3)


def test_the_tank_block_scales_only_the_active_part_and_publishes_its_level():
    harness = BlockHarness("energy_tank", {"tank": {"initial_j": 0.001, "refill_damping_ns_per_m": 0.0}})
    harness.configure()
    harness.feed("demand", [0.0, 0.0, 7.0])  # 2 N of centring, 5 N of cue
    harness.feed("active", [0.0, 0.0, 5.0])
    harness.feed("velocity", [0.0, 0.0, 0.1])
    harness.step()
    assert harness.outputs.force.value[2] == pytest.approx(7.0)
    assert float(harness.outputs.level.value) == pytest.approx(0.001 - 0.5e-3)
    harness.step(2)
    assert harness.outputs.force.value[2] == pytest.approx(2.0)  # the cue held back, the centring kept
    assert float(harness.outputs.level.value) == 0.0 and float(harness.outputs.scale.value) == 0.0


def test_the_robot_side_governor_stops_before_the_wall_and_on_a_stale_command():
    harness = BlockHarness("speed_governor", {"scan_points": 811})
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 811, dtype=np.float32)
    ranges = np.full(811, 30.0, dtype=np.float32)
    harness.feed("angles", angles)
    harness.configure()
    harness.feed("ranges", ranges)
    harness.feed("command", [0.8, 0.0, 0.0])
    harness.step()
    assert harness.outputs.twist.value[0] == pytest.approx(0.8)  # nothing near: untouched
    ahead = np.abs(angles) < 0.4
    ranges[ahead] = (0.9 / np.cos(angles[ahead])).astype(np.float32)  # a wall 0.9 m ahead of the scanner
    harness.feed("ranges", ranges)
    harness.feed("command", [0.8, 0.0, 0.0])
    harness.step()
    assert 0.0 <= harness.outputs.twist.value[0] < 0.8
    harness.inputs.command.max_age_ns = 100_000_000
    harness.advance(200_000_000)  # the link delivered nothing for 200 ms: no command
    harness.inputs.ranges.max_age_ns = 0
    harness.step()
    assert np.all(harness.outputs.twist.value == 0.0)


# -- the composition ------------------------------------------------------------------------------------------------

def test_the_hallway_behind_the_emulated_link_runs_the_same_twice(tmp_path):
    """systems/teleop_sim.yaml on the virtual clock: the link's luck comes from its seeds, so two runs are one
    (the second recorded: its recording holds the link's figures)."""
    from .conftest import SYSTEMS
    from .runtime_helpers import compose

    (tmp_path / "hallway.yaml").write_text((SYSTEMS / "hallway.yaml").read_text())
    text = (SYSTEMS / "teleop_sim.yaml").read_text().replace(
        "\nactivities:\n", "\nactivities:\n  world:\n    params: {time_limit_s: 4.0, plot: false}\n", 1)
    runs = [compose(tmp_path, text, duration=None, name=name, seed=3, record=None if name == "a" else "")
            for name in "ab"]
    assert all(run.outcome.status.name == "SUCCESS" for run in runs), [run.outcome.reasons for run in runs]
    a, b = (np.load(tmp_path / f"run-{name}" / "trajectory.npz") for name in "ab")
    assert a["pose"].shape == b["pose"].shape and a["pose"].tobytes() == b["pose"].tobytes()
    assert a["force_env"].tobytes() == b["force_env"].tobytes()
    assert np.ptp(a["pose"][:, 0]) > 0.1  # the robot drove, behind a link that lost samples
    uplink = (tmp_path / "run-a" / "uplink.log").read_text()
    assert " 0 lost" not in uplink and "lost" in uplink
    # the pings crossed both links: the round trip measured (and given to the predictor) is the emulated one
    metrics = json.loads((tmp_path / "run-a" / "metrics.json").read_text())
    assert 0.18 <= metrics["round_trip_max_s"] <= 0.23 and metrics["link_loss_max"] > 0.0
    assert "round trip" in (tmp_path / "run-a" / "pinger.log").read_text()
    table = json.loads((tmp_path / "run-a" / "results-link-pinger.json").read_text())  # the end-of-run table
    rows = {row["metric"]: row["value"] for row in table["rows"]}
    assert 180 <= rows["round trip p50"] <= 230 and rows["pings unanswered"] > 0.0
    from hapticop.recording.reading import series

    recording = next((tmp_path / "run-b").glob("*.mcap"))
    round_trip = series(recording, "round_trip")
    assert len(round_trip.values) > 10 and 0.18 <= float(round_trip.values[-1]) <= 0.23
    assert len(series(recording, "link_loss").values) and len(series(recording, "link_jitter").values)


def test_the_operators_side_governs_its_commands_on_the_scan_seen_from_the_predicted_pose():
    """Behind a link, the haptic controller's governor models the robot's: the robot a predicted 0.4 m nearer
    to the wall than the scan shows may be commanded less speed, so the commands sent (and the pose predicted
    from them) stay what the governed robot does."""
    harness = BlockHarness("haptic_controller", {"governor": {}, "scan_points": 811})
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 811, dtype=np.float32)
    ranges = np.full(811, 30.0, dtype=np.float32)
    ahead = np.abs(angles) < 0.4
    ranges[ahead] = (1.6 / np.cos(angles[ahead])).astype(np.float32)  # a wall 1.6 m ahead of the scanner
    harness.flags["resources_ready"] = True
    for port, value in (("angles", angles), ("ranges", ranges), ("handle_position", [0.0, 0.0, 0.0]),
                        ("handle_velocity", [0.0, 0.0, 0.0])):
        harness.feed(port, value)
    harness.configure()

    def commanded(travel_m: float | None) -> float:
        harness.feed("handle_position", [0.0, 0.0, -0.04])  # pushed well forward: full speed asked
        if travel_m is not None:
            harness.feed("predicted_travel", [travel_m, 0.0, 0.0])
        harness.step()
        return float(harness.outputs.velocity_setpoint.value[0])

    as_scanned = commanded(None)
    predicted = commanded(0.4)
    assert 0.0 < predicted < as_scanned
    assert commanded(5.0) == 0.0  # predicted past the stop line: no forward command
