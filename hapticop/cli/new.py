"""`hapticop new NAME`: a minimal application that validates and runs, to start from.

One thread, the Falcon (simulated through its real codec, with a scripted hand on its grip) and
one force block; with `--block`, that force block is the author's own, in a module beside the
file, so the first edit can be to a block as well as to the YAML.
"""

from __future__ import annotations

import re
from pathlib import Path

import typer

APPLICATION = """\
# yaml-language-server: $schema={schema}
#
# {name}: the Falcon's handle held at the workspace centre by a spring (written by `hapticop new`).
#   hapticop validate {file}            # check it
#   hapticop compose {file}             # run it: a scripted hand homes the Falcon, pushes, lets go
#   hapticop blocks                     # the blocks you can add; `hapticop blocks NAME` for one
# With a real Falcon: falcon's driver 'usb' (and its firmware), and remove falcon_sim and hand.
version: 1
name: {name}
doc: A spring holding the Falcon's handle at its centre.

threads:
  main:
    period: 1ms                 # the Falcon exchanges frames at 1 kHz
    deploy: main
    schedules:
      0: [mediator]
      1: [mediator, hand, falcon_sim, falcon, spring]

activities:
  mediator: {{block: mediator}}
  falcon:
    block: falcon
    params: {{driver: sim, simulator: falcon_sim}}
  spring:
    block: {spring_block}
    params:
{spring_params}
  falcon_sim: {{block: falcon_simulator}}   # the simulated Falcon behind the falcon block's frames
  hand: {{block: scripted_hand}}            # homes it, then pushes on the grip and lets go

streams:
  handle_position: {{from: falcon.position, to: [spring.position], max_age: 20ms}}
  handle_velocity: {{from: falcon.velocity, to: [spring.velocity], max_age: 20ms}}
  handle_force: {{from: spring.force, to: [falcon.force]}}
  true_handle_position: {{from: falcon_sim.handle_position, to: [hand.handle_position]}}
  true_handle_velocity: {{from: falcon_sim.handle_velocity, to: [hand.handle_velocity]}}
  falcon_leds: {{from: falcon_sim.leds, to: [hand.leds]}}
  hand_force: {{from: hand.hand_force, to: [falcon_sim.hand_force]}}
  hand_buttons: {{from: hand.buttons, to: [falcon_sim.buttons]}}

coordination:
  nets:
    run:
      doc: select schedule 1 at once; stop when the scripted hand is done (or on Ctrl+C)
      places: {{START: , SELECT: , RUNNING: , FINISHED: , STOP: , STOPPED: }}
      marking: {{START: 1}}
      terminal: [STOPPED]
      transitions:
        begin: {{in: [START], out: [SELECT, RUNNING]}}
        finish: {{in: [RUNNING, FINISHED], out: [STOP, STOPPED]}}
  flag_maps:
    run:
      net: run
      converting_sources: {{hand.finished: FINISHED}}
      converting_sinks: {{threads.main.select_schedule.1: SELECT, system.stop: STOP}}
"""

BUILT_IN_SPRING = "      spring: {kp_n_per_m: 200.0, kd_ns_per_m: 1.0}"
OWN_SPRING = "      kp_n_per_m: 200.0"

BLOCK = '''\
"""{name}'s own blocks (written by `hapticop new --block`): found because this file sits beside {file}."""

from __future__ import annotations

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port


class SpringParams(Params):
    kp_n_per_m: float = Field(200.0, ge=0.0, le=3000.0, description="stiffness towards the centre")


class Spring(Block):
    """A spring pulling the handle to the workspace centre: F = -k p, zero while the position is stale."""

    Params = SpringParams
    inputs = {{
        "position": Port("float64", (3,), "m", "handle position, device frame"),
        "velocity": Port("float64", (3,), "m/s", "handle velocity (unused here: add a damper)", required=False),
    }}
    outputs = {{"force": Port("float64", (3,), "N", "force on the handle, device frame")}}
    running_params = frozenset({{"kp_n_per_m"}})  # read every cycle: a live patch needs no re-configuration

    def compute(self) -> None:
        """The time-critical step: read the inputs, write the outputs in place, publish. No allocation."""
        position, force = self.inputs.position, self.outputs.force
        if position.valid:
            force.value[:] = position.value
            force.value *= -self.params.kp_n_per_m
        else:
            force.value[:] = 0.0
        force.publish()

    def clean(self) -> None:
        self.outputs.force.value[:] = 0.0
        self.outputs.force.publish()
'''

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def new(
    name: str = typer.Argument(..., help="the application's name, lower_snake_case: NAME.yaml is written"),
    directory: Path = typer.Option(Path("."), "--dir", help="where to write it"),
    block: bool = typer.Option(False, "--block", help="also write NAME_blocks.py with a force block of your own"),
    force: bool = typer.Option(False, "--force", help="overwrite files that exist"),
) -> None:
    """Write a minimal application that validates and runs: the Falcon and a spring."""
    if not _NAME.match(name):
        typer.echo(f"error: '{name}' is not a lower_snake_case name (letters, digits, _; a letter first)", err=True)
        raise typer.Exit(2)
    yaml_file = directory / f"{name}.yaml"
    module_file = directory / f"{name}_blocks.py"
    targets = [yaml_file] + ([module_file] if block else [])
    existing = [str(p) for p in targets if p.exists()]
    if existing and not force:
        typer.echo(f"error: {', '.join(existing)} exists; --force overwrites", err=True)
        raise typer.Exit(2)
    if not directory.is_dir():
        typer.echo(f"error: {directory} is not a directory", err=True)
        raise typer.Exit(2)
    schema = Path(__file__).resolve().parents[2] / "schemas" / "composition.schema.json"
    yaml_file.write_text(APPLICATION.format(
        name=name, file=yaml_file.name, schema=schema.as_uri() if schema.exists() else "composition.schema.json",
        spring_block=f'"{name}_blocks:Spring"' if block else "spring_damper",
        spring_params=OWN_SPRING if block else BUILT_IN_SPRING))
    if block:
        module_file.write_text(BLOCK.format(name=name, file=yaml_file.name))
    for path in targets:
        typer.echo(f"wrote {path}")
    check = "validate --import-blocks" if block else "validate"  # validate runs no author's code unless asked
    typer.echo(f"next: hapticop {check} {yaml_file} && hapticop compose {yaml_file}")
