"""Running small compositions from tests."""

from __future__ import annotations

import textwrap

from hapticop.runtime.system import RunOptions, RunResult, run_system
from hapticop.units import parse_duration_ns
from hapticop.validation import validate_path


def compose(tmp_path, text: str, *, clock="virtual", duration="1s", seed=0, name="c", on_start=None,
            shutdown_timeout="2s", control=None) -> RunResult:
    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(text))
    validated = validate_path(path)
    assert validated.report.ok, "\n".join(d.to_text() for d in validated.report.diagnostics)
    options = RunOptions(clock=clock, duration_ns=parse_duration_ns(duration) if duration else None, seed=seed,
                         run_dir=tmp_path / f"run-{name}", shutdown_timeout_ns=parse_duration_ns(shutdown_timeout),
                         echo=False, control=control)
    return run_system(validated.graph.loaded, validated.source.text, str(path), options, on_start=on_start)


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
    return PIPELINE.replace("DEPLOY", f"deploy: {deploy}")
