"""Running small compositions from tests."""

from __future__ import annotations

import logging
import textwrap
import threading
import time
from types import SimpleNamespace

import numpy as np

from hapticop.composition.units import parse_duration_ns
from hapticop.runtime.system import RunOptions, RunResult, run_system
from hapticop.validation import validate_path


def compose(tmp_path, text: str, *, clock="virtual", duration="1s", seed=0, name="c", on_start=None,
            shutdown_timeout="5s", control=None, record: str | None = None) -> RunResult:
    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(text))
    validated = validate_path(path)
    assert validated.report.ok, "\n".join(d.to_text() for d in validated.report.diagnostics)
    options = RunOptions(clock=clock, duration_ns=parse_duration_ns(duration) if duration else None, seed=seed,
                         run_dir=tmp_path / f"run-{name}", shutdown_timeout_ns=parse_duration_ns(shutdown_timeout),
                         echo=False, control=control, record=record)
    return run_system(validated, options, on_start=on_start)


PATIENCE_S = 30.0  # what a condition may take on a loaded machine: a bound on hangs, never a speed requirement


def run_until(tmp_path, text: str, condition, what: str, name: str = "c", shutdown_timeout: str = "5s",
              record: str | None = None) -> RunResult:
    """Run `text` on the wall clock until `condition(system)` holds, then shut it down: a test
    waits for what it checks to happen, not for a duration it hopes is long enough. The run
    fails the test if the condition does not hold within PATIENCE_S."""
    missed: list[str] = []

    def operator(system) -> None:
        def watch() -> None:
            deadline = time.monotonic() + PATIENCE_S
            try:
                while not condition(system):
                    if time.monotonic() > deadline:
                        missed.append(f"never happened within {PATIENCE_S:g} s: {what}")
                        return
                    time.sleep(0.01)
            except Exception as error:  # noqa: BLE001 - the test fails on it, in its own thread
                missed.append(f"the condition raised {error!r}")
            finally:
                system.request_shutdown()
        threading.Thread(target=watch, daemon=True).start()

    result = compose(tmp_path, text, clock="realtime", duration=f"{PATIENCE_S * 4:g}s", on_start=operator, name=name,
                     shutdown_timeout=shutdown_timeout, record=record)
    assert not missed, missed[0]
    return result


def steps(system, activity: str) -> int:
    """How many times `activity` has been stepped so far, wherever it runs (from the shared region)."""
    from hapticop.runtime.report import timing

    return timing(system.region, system.composition)["activities"][activity]["steps"]


def standalone(block_class, name: str, params: dict, run_dir, clock, seed: int = 0):
    """One block outside any system, as its hooks see the runtime: its ports unconnected,
    its flags in a dict, `clock` its clock (a VirtualClock a test advances)."""
    from hapticop.runtime.context import ActivityContext, InputPort, OutputPort

    params = block_class.Params(**params)
    interface = block_class.declare(params)
    inputs = SimpleNamespace(**{n: InputPort(n, p, clock.now_ns) for n, p in interface.inputs.items()})
    outputs = SimpleNamespace(**{n: OutputPort(n, p, clock.now_ns) for n, p in interface.outputs.items()})
    context = ActivityContext(name, params, inputs, outputs, dict.fromkeys(interface.flags_written, False), clock,
                              logging.getLogger(f"test.{name}"), np.random.default_rng(seed), run_dir)
    return block_class(context)


PIPELINE = """
version: 1
name: pipeline
threads:
  main:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, noise]}
  slow:
    period: 10ms
    DEPLOY
    schedules: {0: [recorder]}
activities:
  mediator: {block: mediator}
  noise: {block: "tests.blocks:Noise"}
  recorder: {block: "tests.blocks:Recorder"}
streams:
  samples: {from: noise.sample, to: recorder.sample}
"""


def pipeline(deploy: str = "thread") -> str:
    """Seeded noise on a 1 kHz main thread, recorded on a 10 ms thread."""
    return PIPELINE.replace("DEPLOY", f"deploy: {deploy}")


def counting(deploy: str = "thread") -> str:
    """The same shape with built-in blocks only: a counter echoed on the slow thread."""
    return (PIPELINE.replace("DEPLOY", f"deploy: {deploy}")
            .replace('noise: {block: "tests.blocks:Noise"}', "noise: {block: counter}")
            .replace('recorder: {block: "tests.blocks:Recorder"}', "recorder: {block: echo}")
            .replace("{from: noise.sample, to: recorder.sample}", "{from: noise.count, to: recorder.input}"))


COUNTER = """
version: 1
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, counter]}}
activities:
  mediator: {block: mediator}
  counter: {block: counter}
"""

# Coordination that sees the shutdown request and never finishes it.
IGNORES_SHUTDOWN = """
coordination:
  nets:
    ignore:
      places: {IDLE: , S: , SEEN: }
      transitions: {seen: {in: [IDLE, S], out: [SEEN]}}
      marking: {IDLE: 1}
      terminal: [SEEN]
  flag_maps:
    ignore: {net: ignore, tracking_sources: {system.shutdown_requested: S}}
"""


def step_thread(run_dir, path, cycles: int, sample, thread: str = "main", gate: str | None = None) -> list:
    """The composition at `path` on the virtual clock, its one thread `thread` cycled by hand for `cycles`
    milliseconds: `sample(blocks)` (the thread's blocks by activity name) is kept each cycle once the activity
    `gate` runs (from the first cycle without one)."""
    from hapticop.runtime.system import RunOptions, System
    from hapticop.validation import validate_path

    validated = validate_path(path)
    assert validated.report.ok, validated.report.diagnostics
    system = System(validated, RunOptions(clock="virtual", run_dir=run_dir, echo=False))
    loop = system.built.threads[thread]
    rows = []
    try:
        system.start_threads()
        for i in range(cycles):
            system.clock.advance_to(i * 1_000_000)
            loop.cycle()
            if gate is None or system.state(gate).flag_name == "running":
                rows.append(sample({name: runner.block for name, runner in loop.runners.items()}))
    finally:
        for runner in loop.runners.values():
            runner.block.clean()
        system.writer.stop()
        system.built = system.main = None
        system.region.close()
    return rows
