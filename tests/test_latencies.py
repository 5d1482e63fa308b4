"""End-to-end latencies: origins travel with samples through activities, threads and processes."""

from __future__ import annotations

import pytest

from hapticop.runtime.deadlines import START_MARGIN_NS, first_deadline, phases
from hapticop.validation import validate_text
from tests.runtime_helpers import compose

CHAIN = """
version: 1
name: chain
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, source, relay]}
  slow:
    period: 4ms
    DEPLOY
    schedules: {0: [sink]}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  relay: {block: echo}
  sink: {block: echo}
streams:
  count: {from: source.count, to: relay.input}
  relayed: {from: relay.output, to: sink.input}
latencies:
  counted_to_sink: {from: source.count, to: sink.input}
  counted_to_relay: {from: source.count, to: relay.input}
"""


def test_origins_cross_activities_and_threads_under_the_virtual_clock(tmp_path):
    result = compose(tmp_path, CHAIN.replace("DEPLOY", "deploy: thread"), duration="1s")
    latencies = result.timing["latencies"]
    relay, sink = latencies["counted_to_relay"], latencies["counted_to_sink"]
    assert (relay["from"], relay["to"]) == ("source.count", "relay.input")
    # Same thread, relay after source: the origin arrives in the same instant, every cycle.
    assert relay["samples"] > 900 and relay["latency_us"]["max"] == 0
    # The 4 ms sink steps after main at shared deadlines: it sees the newest count, born that instant.
    # (As the run ends, the source cleans first and the last count relayed is a cycle old: the shutdown's,
    # which the run's timing leaves out.)
    assert sink["samples"] > 200 and sink["histogram_us"] == {"0": sink["samples"]}


def test_origins_reach_a_thread_in_its_own_process(tmp_path):
    result = compose(tmp_path, CHAIN.replace("DEPLOY", "deploy: process"), clock="realtime", duration="1s")
    sink = result.timing["latencies"]["counted_to_sink"]
    assert sink["samples"] >= 1  # the child may start late on a busy machine, but it does see origins
    assert 0 <= sink["latency_us"]["max"] < 60e6  # a real age, not an unset origin (that would be the uptime)
    assert result.timing["threads"]["slow"]["cpu_percent"] is not None


def test_a_latency_must_name_ports_that_data_connects():
    text = CHAIN.replace("DEPLOY", "deploy: thread").replace(
        "counted_to_relay: {from: source.count, to: relay.input}",
        "backwards: {from: relay.output, to: relay.input}\n  typo: {from: source.cont, to: sink.output}")
    report = validate_text(text, "chain.yaml").report
    found = {(d.rule, d.path) for d in report.errors}
    assert ("latency-unreachable", ("latencies", "backwards")) in found
    assert ("unknown-port", ("latencies", "typo", "from")) in found
    assert ("unknown-port", ("latencies", "typo", "to")) in found


def test_auto_phases_stagger_equal_periods_highest_priority_first():
    text = """
version: 1
threads:
  main: {period: 1ms, priority: 38, deploy: main, phase: auto, schedules: {0: [mediator]}}
  fieldbus: {period: 1ms, priority: 45, phase: auto, schedules: {0: []}}
  plain: {period: 1ms, phase: auto, schedules: {0: []}}
  lidar: {period: 15Hz, phase: auto, schedules: {0: []}}
  fixed: {period: 1ms, phase: 100us, schedules: {0: []}}
  together: {period: 1ms, schedules: {0: []}}
activities:
  mediator: {block: mediator}
"""
    composition = validate_text(text, "p.yaml").graph.loaded.composition
    got = phases(composition)
    assert got["fieldbus"] == 0 and got["main"] == 333_333 and got["plain"] == 666_666
    assert got["lidar"] == 0 and got["fixed"] == 100_000 and got["together"] == 0  # the default: no offset


@pytest.mark.parametrize("now", [0, 1, 999_999, 1_000_000, 123_456_789])
def test_first_deadline_is_on_the_grid_and_far_enough_ahead(now):
    epoch, period, phase = 5_000, 1_000_000, 250_000
    deadline = first_deadline(epoch, period, phase, now)
    assert (deadline - epoch - phase) % period == 0
    assert now + START_MARGIN_NS <= deadline < now + START_MARGIN_NS + period or deadline == epoch + phase


def test_the_simulation_timer_accumulates_without_allocating():
    import numpy as np

    from hapticop.runtime.context import SimulationTimer

    totals = np.zeros(2, dtype=np.int64)
    timer = SimulationTimer(totals, 1)
    for _ in range(3):
        with timer:
            sum(range(1000))
    assert totals[0] == 0 and totals[1] > 0
    with SimulationTimer():  # a context without a region: counts nothing, fails nothing
        pass


SIMULATING = """
version: 1
name: simulating
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, source, world]}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  world: {block: "tests.blocks:Simulator"}
"""


def test_the_report_tells_the_system_from_its_simulators(tmp_path):
    result = compose(tmp_path, SIMULATING, clock="realtime", duration="0.5s", name="simulating")
    cpu = result.timing["cpu"]
    assert cpu["simulators_percent"] > 0
    assert cpu["without_simulators_percent"] == pytest.approx(cpu["loops_percent"] - cpu["simulators_percent"],
                                                              abs=0.11)
    assert result.timing["activities"]["world"]["simulation_us_per_step"] > 0
    assert "simulation_us_per_step" not in result.timing["activities"]["source"]
