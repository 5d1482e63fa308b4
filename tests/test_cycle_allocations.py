"""The cycle path leaves nothing allocated behind: threads, LCSMs, streams, coordination."""

import contextlib
import time
import tracemalloc

import numpy as np
import pytest

from hapticop.runtime.system import RunOptions, System
from hapticop.testing import stepped_system
from hapticop.validation import validate_text

from .runtime_helpers import counting


def _assert_nothing_stays(system, run_cycles, aside: tuple[str, ...] = ()) -> None:
    """What `run_cycles` leaves allocated, the log writer's thread aside (not the cycle's business),
    and the files `aside` names (what they hold is data in flight, replaced as it goes)."""
    while not system.writer.queue.empty():
        time.sleep(0.01)
    only_cycle = [tracemalloc.Filter(False, "*/logs.py"), tracemalloc.Filter(False, "*/threading.py"),
                  *(tracemalloc.Filter(False, pattern) for pattern in aside)]
    tracemalloc.start()
    before = tracemalloc.take_snapshot().filter_traces(only_cycle)
    run_cycles()
    after = tracemalloc.take_snapshot().filter_traces(only_cycle)
    tracemalloc.stop()
    grown = sum(stat.size_diff for stat in after.compare_to(before, "filename") if stat.size_diff > 0)
    assert grown < 4096, [str(s) for s in after.compare_to(before, "lineno")[:5]]


@contextlib.contextmanager
def _virtual_system(tmp_path, text: str, file: str):
    """A valid composition built on the virtual clock, its threads started, and `cycles(start, count)`
    stepping every thread each millisecond; released, its blocks cleaned (links closed, worlds
    withdrawn: this process runs more tests), however the test ends."""
    validated = validate_text(text, file)
    assert validated.report.ok, validated.report.diagnostics
    with stepped_system(validated, tmp_path) as (system, threads):
        system.start_threads()

        def cycles(start: int, count: int) -> None:
            for i in range(start, start + count):
                system.clock.advance_to(i * 1_000_000)
                for thread in threads.values():
                    thread.cycle()

        yield system, threads, cycles


@pytest.mark.parametrize("record", ["", "record: {}"])
def test_steady_cycles_allocate_nothing_that_stays(tmp_path, record):
    """Recorded or not: a recorded stream's writer pushes into the recorder's ring too (the
    recorder itself, here drained by the main process between cycles, is set aside)."""
    text = counting() + record
    validated = validate_text(text, "alloc.yaml")
    assert validated.report.ok, validated.report.diagnostics
    system = System(validated, RunOptions(clock="virtual", run_dir=tmp_path, echo=False))
    recorder, system.observer.recorder = system.observer.recorder, None
    assert (recorder is not None) == bool(record)
    try:
        threads = system.built.threads
        main, slow = threads["main"], threads["slow"]
        system.start_threads()

        def cycles(start, count):
            for i in range(start, start + count):
                system.clock.advance_to(i * 1_000_000)
                main.cycle()
                if i % 10 == 0:
                    slow.cycle()

        cycles(0, 2_000)  # everything is running and warm
        assert system.state("recorder").flag_name == "running"
        _assert_nothing_stays(system, lambda: cycles(2_000, 10_000))
        if recorder is not None:
            summary, _ = recorder.stop()
            assert summary["streams"]["samples"]["written"] > 10_000
    finally:
        system.writer.stop()
        system.built = system.main = None
        system.region.close()


def test_the_simulated_falcon_operator_and_world_allocate_nothing_that_stays(tmp_path):
    """The Falcon block, its simulator, the operator driving it and the world recording, on two threads."""
    from .conftest import FIXTURES

    text = ((FIXTURES / "simulation_process.yaml").read_text()
            .replace("time_limit_s: 1.0", "time_limit_s: 60.0").replace("time_limit_s: 5.0", "time_limit_s: 60.0"))
    with _virtual_system(tmp_path, text, "sim.yaml") as (system, threads, cycles):
        operator = threads["simulation"].runners["operator"].block
        cycles(0, 3_000)  # homed, and the operator drives
        assert system.state("falcon").flag_name == "running" and operator.driving_since_ns is not None
        _assert_nothing_stays(system, lambda: cycles(3_000, 5_000))


SIMULATED_WHEELS = """
version: 1
name: wheels
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, drive, ropod_plant, ethercat, ropod]}}
activities:
  mediator: {block: mediator}
  drive: {block: "tests.blocks:ConstantTwist", params: {twist: [0.3, 0.0, 0.0]}}
  ropod_plant: {block: ropod_plant}
  ethercat: {block: ethercat_master, params: {driver: sim, simulator: ropod_plant}}
  ropod: {block: ropod_controller}
streams:
  velocity_setpoint: {from: drive.velocity_setpoint, to: ropod.velocity_setpoint}
  wheel_sensors: {from: ethercat.wheel_sensors, to: ropod.wheel_sensors}
  wheel_commands: {from: ropod.wheel_commands, to: ethercat.wheel_commands}
"""


def test_the_simulated_wheels_exchange_without_allocating(tmp_path):
    """The master and the simulated ropod talk over their datagram link every cycle."""
    with _virtual_system(tmp_path, SIMULATED_WHEELS, "wheels.yaml") as (system, _, cycles):
        cycles(0, 2_000)
        assert system.state("ethercat").flag_name == "running" and system.state("ropod_plant").flag_name == "running"
        assert system.flag("ethercat.operational")  # the plant answers every frame
        _assert_nothing_stays(system, lambda: cycles(2_000, 5_000))


def test_the_virtual_wall_and_its_scripted_hand_allocate_nothing_that_stays(tmp_path):
    """systems/wall.yaml: the Falcon, the wall, the button, the force limit, the simulated Falcon and the hand."""
    from .conftest import SYSTEMS

    with _virtual_system(tmp_path, (SYSTEMS / "wall.yaml").read_text(), "wall.yaml") as (system, threads, cycles):
        cycles(0, 2_000)  # homed, the grip in place, the hand about to push
        assert system.state("wall").flag_name == "running" and system.state("limit").flag_name == "running"
        _assert_nothing_stays(system, lambda: cycles(2_000, 1_500))  # pushing into the wall, and holding
        assert threads["main"].runners["limit"].block.outputs.force.value[1] > 0


EVERY_EFFECT = """
version: 1
name: effects
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, hand, falcon_sim, falcon, wall, spring, fluid, box, ball, sum, limit]}
activities:
  mediator: {block: mediator}
  hand: {block: scripted_hand}
  falcon_sim: {block: falcon_simulator}
  falcon: {block: falcon, params: {driver: sim, simulator: falcon_sim}}
  wall: {block: virtual_wall, params: {wall: {point_m: [0.0, -0.006, 0.0], normal: [0.0, 1.0, 0.0]}}}
  spring: {block: spring_damper, params: {spring: {kp_n_per_m: 20.0}}}
  fluid: {block: viscous_field}
  box: {block: workspace_limit, params: {limit: {kind: box, half_size_m: [0.005, 0.005, 0.005]}}}
  ball: {block: workspace_limit, params: {limit: {kind: sphere, radius_m: 0.006}}}
  sum: {block: force_sum, params: {inputs: 5}}
  limit: {block: force_limit}
streams:
  position: {from: falcon.position, to: [wall.position, spring.position, fluid.position, box.position, ball.position]}
  velocity: {from: falcon.velocity, to: [wall.velocity, spring.velocity, fluid.velocity, box.velocity, ball.velocity]}
  f1: {from: wall.force, to: sum.force_1}
  f2: {from: spring.force, to: sum.force_2}
  f3: {from: fluid.force, to: sum.force_3}
  f4: {from: box.force, to: sum.force_4}
  f5: {from: ball.force, to: sum.force_5}
  total: {from: sum.force, to: limit.demand}
  device: {from: limit.force, to: falcon.force}
  true_position: {from: falcon_sim.handle_position, to: hand.handle_position}
  true_velocity: {from: falcon_sim.handle_velocity, to: hand.handle_velocity}
  leds: {from: falcon_sim.leds, to: hand.leds}
  hand_force: {from: hand.hand_force, to: falcon_sim.hand_force}
"""


def test_every_haptic_effect_summed_and_limited_allocates_nothing_that_stays(tmp_path):
    """The spring, the fluid, both workspace limits and the wall, added by force_sum, on the simulated Falcon."""
    with _virtual_system(tmp_path, EVERY_EFFECT, "effects.yaml") as (system, threads, cycles):
        main = threads["main"]
        cycles(0, 1_900)
        assert system.state("sum").flag_name == "running"
        _assert_nothing_stays(system, lambda: cycles(1_900, 1_000))  # the hand pushes down through the fields
        names = ("wall", "spring", "fluid", "box", "ball")
        felt = dict.fromkeys(names, 0.0)
        for i in range(2_900, 3_400):  # holding, then letting go: the handle springs back up
            cycles(i, 1)
            for name in names:
                felt[name] = max(felt[name], float(np.abs(main.runners[name].block.outputs.force.value).max()))
        assert all(felt.values()), felt  # each one rendered something


def test_a_stream_stale_on_every_arrival_allocates_nothing_that_stays(tmp_path):
    """Judging each arrival against max_age, and saying so every 10 s, leaves nothing behind."""
    from .test_stale_inputs import linked

    with _virtual_system(tmp_path, linked(0.07, "50ms"), "stale.yaml") as (system, _, cycles):
        cycles(0, 2_000)  # stale from the first arrivals on, said once already
        # said again at 10 s; the emulated link's 70 packets in flight are new ones, not more ones
        _assert_nothing_stays(system, lambda: cycles(2_000, 12_000), aside=("*/network/link.py",))
    assert (tmp_path / "reader.log").read_text().count("every sample arrives stale") == 2


def test_a_commands_range_check_allocates_nothing():
    """The check a command's reader runs on each new sample (hapticop/blocks/bounds.py), good or refused."""
    from hapticop.blocks.bounds import Bounds
    from hapticop.blocks.interface import Port
    from hapticop.testing import allocation_stats

    bounds = Bounds(Port("float64", (3,), range=(-10.0, 10.0)), "setpoint")
    good, bad = np.array([0.3, 0.0, -0.2]), np.array([np.nan, 1e300, 0.0])
    retained, peak = allocation_stats(lambda: (bounds.admits(good), bounds.admits(bad)), 1000)
    # retained: the counters themselves (Python ints); peak: numpy's transient ufunc scratch, no array
    assert retained < 256 and peak < 2048


def test_the_bilateral_set_up_with_its_scene_world_allocates_nothing_that_stays(tmp_path):
    """systems/bilateral.yaml: two Falcons and their simulators, the coupling, and the scene world putting the
    follower's handle in its scene and publishing the wall's push on it."""
    from .conftest import SYSTEMS

    path = SYSTEMS / "bilateral.yaml"
    with _virtual_system(tmp_path, path.read_text(), str(path)) as (system, threads, cycles):
        cycles(0, 3_000)  # both homed, the leader's hand pushing
        assert system.state("world").flag_name == "running" and system.state("follower").flag_name == "running"
        _assert_nothing_stays(system, lambda: cycles(3_000, 1_500))  # the follower against the wall, held
        assert threads["main"].runners["world"].block.outputs.follower_handle_force.value[2] > 0
