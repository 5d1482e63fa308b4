"""Replaying a recorded hallway run: the haptic controller's outputs come back equal to the bit under
the virtual clock, a tampered recording is a reported mismatch, a bad one a located error, and the
hallway world's trajectory, metrics and picture made from the recording are the run's own."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hapticop.cli.main import app
from hapticop.composition.lcsm import State
from hapticop.observe.replay import ReplayError, open_run, replay, results, validated_rewrite
from hapticop.observe.rewrite import PACED
from hapticop.recording.parameters import events
from hapticop.recording.reading import series
from hapticop.sim.recorded_run import integrate

from .conftest import ROOT
from .recordings import rewrite_recording
from .runtime_helpers import compose
from .test_modes import MODES

cli = CliRunner()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 4 s hallway run under the virtual clock, every stream recorded: the haptic loop runs from
    about 1 s, the operator drives from about 1.3 s, and the world leaves its results."""
    tmp = tmp_path_factory.mktemp("hallway")
    text = (ROOT / "systems" / "hallway.yaml").read_text() + "\nrecord: {}\n"
    result = compose(tmp, text, duration="4s", name="hallway")
    assert not any(s["dropped"] for s in result.recording["streams"].values())
    return tmp / "run-hallway"



def test_the_haptic_controllers_outputs_replay_equal_to_the_bit(recorded):
    path = recorded / "hallway.mcap"
    [haptic] = replay(path)  # by default: the haptic controller
    assert (haptic.activity, haptic.block, haptic.thread) == ("haptic", "haptic_controller", "main")
    assert set(haptic.inputs) == {"handle_position", "handle_velocity", "rendered_scan",
                                  "platform_velocity"}
    compared = {c.stream: c for c in haptic.compared}
    assert set(compared) == {"handle_force", "velocity_setpoint", "environment_force"}
    for stream, c in compared.items():
        # the same code on the same samples in the same order: equal, not merely close
        assert c.ok and c.max_diff == 0.0 and c.samples == len(series(path, stream).values) > 2500
    assert np.abs(series(path, "velocity_setpoint").values).max() > 0.1  # the robot was driven: a real test
    assert haptic.cycles == len(series(path, "cycles/haptic").values) and haptic.computed > 2500
    assert not haptic.diverged


def test_a_replay_is_a_rewritten_composition_that_validates(recorded):
    """What replays the controller is a composition of its own, validated as any file is: the
    controller with its recorded block and parameters, fed only by a recorded_source on its inputs'
    streams, the two on a thread of their own; nothing else of the hallway is in it."""
    run = open_run(recorded / "hallway.mcap")
    rewritten, validated = validated_rewrite(run, "haptic")
    loaded = validated.graph.loaded
    composition = loaded.composition
    assert {name: a.spec.block for name, a in loaded.activities.items()} == {
        "mediator": "mediator", "recorded": "recorded_source", "haptic": "haptic_controller"}
    assert loaded.activities["haptic"].params == run.loaded.activities["haptic"].params
    assert composition.threads[PACED].schedules[0] == ["recorded", "haptic"]
    inputs = {name: spec for name, spec in composition.streams.items()
              if any(r.startswith("haptic.") for r in spec.readers)}
    assert set(inputs) == {"handle_position", "handle_velocity", "rendered_scan", "platform_velocity"}
    assert all(spec.writer.startswith("recorded.") for spec in inputs.values())
    for name, spec in inputs.items():  # each stream as the run had it: its policy and max_age
        assert spec.policy == run.loaded.composition.streams[name].policy
        assert spec.max_age == run.loaded.composition.streams[name].max_age
    assert composition.record.streams == ["handle_force", "velocity_setpoint", "environment_force"]
    assert rewritten.start_ns <= int(series(recorded / "hallway.mcap", "cycles/haptic").publish_ns[0])


def test_replay_on_the_command_line_says_equal_and_exits_0(recorded):
    result = cli.invoke(app, ["replay", str(recorded / "hallway.mcap"), "--activity", "haptic"])
    assert result.exit_code == 0, result.output
    assert "haptic (haptic_controller, thread main)" in result.output
    assert result.output.count("max |diff| 0 ") == 3 and "equal" in result.output


def test_a_changed_output_sample_is_a_mismatch_at_its_time_and_element(recorded, tmp_path):
    path = recorded / "hallway.mcap"
    number = 2000
    tampered = rewrite_recording(path, tmp_path / "t.mcap",
                        sample=("/streams/handle_force", number, lambda v: v.__setitem__(2, v[2] + 0.25)))
    [haptic] = replay(tampered)
    compared = {c.stream: c for c in haptic.compared}
    force = compared["handle_force"]
    assert not haptic.ok and not force.ok and force.mismatches == 1
    assert force.max_diff == pytest.approx(0.25)
    assert f"(sample {number}): handle_force[2] replayed" in force.first
    assert compared["velocity_setpoint"].ok and compared["environment_force"].ok
    result = cli.invoke(app, ["replay", str(tampered)])
    assert result.exit_code == 1 and "MISMATCH" in result.output
    assert cli.invoke(app, ["replay", str(tampered), "--tolerance", "0.3"]).exit_code == 0


def test_a_changed_parameter_is_a_mismatch(recorded, tmp_path):
    def stiffer(parameters):
        parameters["haptic"]["centring"]["kp_n_per_m"] *= 1.5

    tampered = rewrite_recording(recorded / "hallway.mcap", tmp_path / "p.mcap", parameters=stiffer)
    [haptic] = replay(tampered)
    force = {c.stream: c for c in haptic.compared}["handle_force"]
    assert not force.ok and force.max_diff > 0.01 and "handle_force[" in force.first
    assert cli.invoke(app, ["replay", str(tampered)]).exit_code == 1


@pytest.mark.parametrize(("change", "expected"), [
    ({"without_topic": "/streams/rendered_scan"},
     "activity 'haptic' cannot be replayed: its input stream 'rendered_scan' was not recorded"),
    ({"attachments": False}, "no composition.yaml attached"),
    ({"without_topic": "/streams/cycles/haptic"},  # a recording made before cycles were recorded
     "activity 'haptic' cannot be replayed: its cycles ('cycles/haptic') were not recorded"),
    ({"parameters": lambda p: p["haptic"].__setitem__("scan_points", "many")},
     "parameters.json, activity 'haptic', scan_points: "),
])
def test_a_recording_that_cannot_be_replayed_is_a_located_error(recorded, tmp_path, change, expected):
    broken = rewrite_recording(recorded / "hallway.mcap", tmp_path / "b.mcap", **change)
    with pytest.raises(ReplayError, match="^" + str(broken)) as raised:
        replay(broken, ["haptic"])
    assert expected in str(raised.value)
    result = cli.invoke(app, ["replay", str(broken), "-a", "haptic"])
    assert result.exit_code == 2 and expected in result.output and "Traceback" not in result.output


def test_a_replayed_life_cycle_that_leaves_the_recorded_one_is_reported(recorded, tmp_path):
    """The recorded cycles say the controller was paused in one cycle where it ran: the replay says
    where its life cycle and the run's part, and the command exits 1."""
    number = 2000

    def paused(row):
        assert row[0] == State.RUNNING  # the controller runs at 2 s
        row[0] = State.PAUSING

    tampered = rewrite_recording(recorded / "hallway.mcap", tmp_path / "p.mcap",
                        sample=("/streams/cycles/haptic", number, paused))
    [haptic] = replay(tampered, ["haptic"])
    assert not haptic.ok and all(c.ok for c in haptic.compared)
    assert "the run's life cycle was pausing, the replay's running" in haptic.diverged
    result = cli.invoke(app, ["replay", str(tampered), "-a", "haptic"])
    assert result.exit_code == 1 and "DIVERGED: at " in result.output


def test_bad_files_and_activities_are_located_errors(recorded, tmp_path):
    path = recorded / "hallway.mcap"
    text = tmp_path / "not.mcap"
    text.write_text("version: 1\n")
    for args, expected in (
        ([str(text)], f"error: {text} is not a finished MCAP recording"),
        ([str(tmp_path / "absent.mcap")], f"error: cannot read {tmp_path / 'absent.mcap'}"),
        ([str(path), "-a", "nobody"], f"error: {path}: the recorded composition has no activity 'nobody' (it has: "),
        ([str(path), "-a", "mediator"], f"error: {path}: activity 'mediator' cannot be replayed: none of its output"),
    ):
        result = cli.invoke(app, ["replay", *args])
        assert result.exit_code == 2, result.output
        assert expected in result.output and "Traceback" not in result.output


def test_the_worlds_results_from_the_recording_are_the_runs_own(recorded, tmp_path):
    """The hallway world replayed from the recording leaves the trajectory, metrics, results and
    picture the run left, to the byte (the operator it judges configured beside it says its variant)."""
    out = tmp_path / "report"
    [world], files = results(recorded / "hallway.mcap", out)
    assert world.activity == "world" and world.ok
    assert sorted(f.name for f in files) == ["metrics.json", "results.json", "run.png", "trajectory.npz"]
    for name in ("metrics.json", "results.json", "run.png"):
        assert (out / name).read_bytes() == (recorded / name).read_bytes(), name
    with np.load(out / "trajectory.npz") as mine, np.load(recorded / "trajectory.npz") as theirs:
        assert sorted(mine.files) == sorted(theirs.files)
        for key in theirs.files:
            assert np.array_equal(mine[key], theirs[key]), key
    assert json.loads((out / "metrics.json").read_text())["t_end_s"] > 2.0  # the operator drove for seconds


def test_report_on_the_command_line(recorded, tmp_path):
    result = cli.invoke(app, ["report", str(recorded / "hallway.mcap"), "-o", str(tmp_path / "r")])
    assert result.exit_code == 0, result.output
    assert f"wrote {tmp_path / 'r' / 'run.png'}" in result.output and "stop error" in result.output
    counters = tmp_path / "c.mcap"
    counters.write_bytes(b"")
    result = cli.invoke(app, ["report", str(counters)])
    assert result.exit_code == 2 and "is not a finished MCAP recording" in result.output


def test_a_run_with_no_world_gets_the_hallways_metrics_and_picture_from_its_streams(recorded, tmp_path):
    """--from-streams ignores the world: the path is the ropod controller's odometry, so the metrics
    come close to the world's own (true pose) without equalling them."""
    out = tmp_path / "streams"
    result = cli.invoke(app, ["report", str(recorded / "hallway.mcap"), "--from-streams", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "from the streams velocity_setpoint, platform_velocity, environment_force" in result.output
    assert (out / "run.png").stat().st_size > 10_000
    mine, theirs = (json.loads((d / "metrics.json").read_text()) for d in (out, recorded))
    assert mine["ended_by"] == theirs["ended_by"]
    assert mine["e_stop_m"] == pytest.approx(theirs["e_stop_m"], abs=0.05)
    assert mine["side_clearance_min_m"] == pytest.approx(theirs["side_clearance_min_m"], abs=0.01)
    assert mine["t_end_s"] == pytest.approx(theirs["t_end_s"], abs=0.2)


def test_without_odometry_the_streams_report_says_what_is_missing(recorded, tmp_path):
    broken = rewrite_recording(recorded / "hallway.mcap", tmp_path / "o.mcap",
                               without_topic="/streams/platform_velocity")
    result = cli.invoke(app, ["report", str(broken), "--from-streams"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{broken}: no recorded stream from a ropod_controller block's 'platform_velocity' port" in result.output
    unknown = cli.invoke(app, ["report", str(recorded / "hallway.mcap"), "--from-streams", "--hallway", "H9"])
    assert unknown.exit_code == 2 and "--hallway H9: not a hallway" in unknown.output


def test_odometry_integrates_a_twist_held_between_samples():
    times = np.arange(0, 1_000_000_001, 1_000_000, dtype=np.int64)  # 1 s at 1 kHz
    straight = integrate(times, np.tile([1.0, 0.0, 0.0], (len(times), 1)), (0.5, 0.0, 0.0))
    assert straight[-1] == pytest.approx([1.5, 0.0, 0.0])
    half_turn = integrate(times, np.tile([1.0, 0.0, np.pi], (len(times), 1)), (0.0, 0.0, 0.0))
    assert half_turn[-1] == pytest.approx([0.0, 2 / np.pi, np.pi], abs=1e-6)  # a half circle of radius 1/pi
    sideways = integrate(times, np.tile([0.0, 1.0, 0.0], (len(times), 1)), (0.0, 0.0, np.pi / 2))
    assert sideways[-1] == pytest.approx([-1.0, 0.0, np.pi / 2])  # the robot's left is -x when it faces +y


def test_a_wall_clock_recording_replays_cycle_for_cycle(tmp_path, figure):
    """On the wall clock the recording says what each cycle saw (`cycles/haptic`): the haptic
    controller's outputs come back equal to the bit, overruns, missed cycles and stale scans included.
    The missed cycles are kept as a figure (`pytest -v`)."""
    text = (ROOT / "systems" / "hallway.yaml").read_text() + "\nrecord: {}\n"
    result = compose(tmp_path, text, clock="realtime", duration="4s", name="hallway")
    assert not any(s["dropped"] for s in result.recording["streams"].values())
    path = tmp_path / "run-hallway" / "hallway.mcap"
    [haptic] = replay(path)
    gaps = np.diff(series(path, "cycles/haptic").publish_ns)
    figure(f"haptic: {haptic.cycles} cycles, {int((gaps > 1_500_000).sum())} gaps longer than 1.5 periods")
    assert not haptic.diverged
    for c in haptic.compared:
        figure(f"{c.stream}: {c.samples} samples, {c.mismatches} differ, max |diff| {c.max_diff:g}")
        assert c.samples > 1000 and c.ok and c.max_diff == 0.0, c.first


def test_without_a_haptic_controller_every_activity_with_recorded_inputs_replays(tmp_path):
    """The desk's virtual wall: the wall, the button and the force limit each replay from their own
    recorded inputs, equal to the bit; the simulators and the Falcon (which needs its simulator) do not."""
    text = (ROOT / "systems" / "wall.yaml").read_text() + "\nrecord: {}\n"
    compose(tmp_path, text, duration="2s", name="wall")
    replayed = replay(tmp_path / "run-wall" / "wall.mcap")
    assert [(r.activity, r.block) for r in replayed] == [("wall", "virtual_wall"), ("grip", "button"),
                                                         ("limit", "force_limit")]
    assert all(r.ok and r.cycles > 1900 for r in replayed)
    assert all(c.max_diff == 0.0 for r in replayed for c in r.compared)


# A counter on a 1 kHz thread of its own feeds a sum on another, whose every 10th cycle sleeps 5 ms
# before looking at its input: its thread overruns and misses cycles while the counter goes on
# publishing, and the input, 3 ms old at most, is judged by the time the step began.
STALLING = """
version: 1
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator]}}
  feed: {period: 1ms, schedules: {0: [count]}}
  work: {period: 1ms, schedules: {0: [sum, echo]}}
activities:
  mediator: {block: mediator}
  count: {block: counter}
  sum: {block: "tests.blocks:SlowSum", params: {every: 10, sleep_ms: 5}}
  echo: {block: echo, params: {shape: [3]}}
streams:
  counts: {from: count.count, to: [sum.value], max_age: 3ms}
  totals: {from: sum.total, to: [echo.input]}
record: {}
"""


def test_a_wall_clock_run_that_misses_cycles_replays_to_the_bit(tmp_path):
    """The cycles a slow cycle made the thread miss are not replayed, the samples the counter published
    while the sum slept are seen by the cycle that saw them, and `valid` is judged at the step's time
    in the run as in the replay: every sum comes back equal."""
    result = compose(tmp_path, STALLING, clock="realtime", duration="2s", name="stalling")
    assert not any(s["dropped"] for s in result.recording["streams"].values())
    path = tmp_path / "run-stalling" / "stalling.mcap"
    cycles = series(path, "cycles/sum").publish_ns
    assert (np.diff(cycles) > 3_000_000).sum() > 20, "the slow cycles made the thread miss cycles"
    [replayed] = replay(path, ["sum"], trusted=True)  # its block is a test module: trusted by name
    [totals] = replayed.compared
    assert totals.samples > 500 and totals.ok and totals.max_diff == 0.0, totals.first
    assert not replayed.diverged


RECORDED_MODES = (MODES.replace("grip, gain]", "grip, gain, echo]")
                  .replace("activities:\n", "activities:\n  echo: {block: echo, params: {dtype: float64}}\n")
                  + "streams:\n  gains: {from: gain.gain, to: [echo.input]}\nrecord: {}\n")


def test_parameter_events_still_in_the_log_writers_queue_at_the_end_are_recorded(tmp_path, monkeypatch):
    """The recorder takes parameter events from the system's log, which a writer thread fills off the real-time
    path. A writer behind at the end of the run (a busy machine; here one that takes 50 ms a line) must still
    have every event in the file before the recorder takes its last look."""
    import time

    from hapticop.runtime.logs import LogWriter

    write = LogWriter._write

    def slow(self, item):
        time.sleep(0.05)
        write(self, item)

    monkeypatch.setattr(LogWriter, "_write", slow)
    compose(tmp_path, RECORDED_MODES, duration="300ms", name="modes")
    path = tmp_path / "run-modes" / "modes.mcap"
    gains = [(e.revision, e.changed, e.parameters["gain"]) for e in events(path) if e.activity == "gain"]
    assert gains == [(1, ("gain",), 5.0), (2, ("gain",), 1.0)]


@pytest.mark.parametrize("clock", ["virtual", "realtime"])
def test_a_recording_with_live_retunes_replays_through_them(tmp_path, clock):
    """A mode retunes the gain while the grip is held: the recording has each parameter event with its
    diff, and the gain's replay hands its block the same parameters in the same cycles."""
    compose(tmp_path, RECORDED_MODES, clock=clock, duration="400ms", name="modes")
    path = tmp_path / "run-modes" / "modes.mcap"
    gains = [(e.revision, e.changed, e.parameters["gain"]) for e in events(path) if e.activity == "gain"]
    assert gains == [(1, ("gain",), 5.0), (2, ("gain",), 1.0)]
    [replayed] = replay(path, ["gain"], trusted=True)  # its blocks are test modules: trusted by name
    [published] = replayed.compared
    recorded = series(path, "gains").values
    assert set(recorded.tolist()) == {1.0, 5.0}  # the run published with both gains: the replay must too
    assert published.ok and published.samples == len(recorded) and not replayed.diverged, published.first
