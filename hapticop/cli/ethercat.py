"""`hapticop ethercat ...`: the emulated ropod segment, a private network for it, and faults."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import typer

ethercat = typer.Typer(help="The emulated ropod EtherCAT segment (root).", no_args_is_help=True, add_completion=False)


@ethercat.command("sandbox", context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def sandbox(
    context: typer.Context,
    interface: str = typer.Option("hapticop-ecat0", help="the master's end of the veth pair"),
    peer: str = typer.Option("hapticop-esc0", help="the emulator's end"),
    seed: int = typer.Option(0, help="seed of the emulated robot"),
) -> None:
    """Run COMMAND (after --) in a private network namespace with the emulated segment on a veth pair.

    The namespace, the pair and the emulator exist only while COMMAND runs; the emulator's
    control socket is in $HAPTICOP_ECAT_CONTROL for `hapticop ethercat fault`, and the file where it
    publishes the robot's true pose in $HAPTICOP_ECAT_TRUTH for the `ropod_truth` block.
    """
    from hapticop.devices.ethercat.emulator.sandbox import Sandbox, namespace_problem
    from hapticop.devices.ethercat.emulator.truth import TRUTH_ENV

    command = list(context.args)
    if not command:
        typer.echo("error: give the command to run after --, e.g. "
                   "hapticop ethercat sandbox -- hapticop compose systems/hallway_ethercat.yaml", err=True)
        raise typer.Exit(2)
    problem = namespace_problem()
    if problem:
        typer.echo(f"error: {problem}", err=True)
        raise typer.Exit(1)
    try:
        with Sandbox(interface, peer, seed=seed) as box:
            typer.echo(f"emulated ropod segment on {peer}, master interface {interface}; "
                       f"control socket {box.control}", err=True)
            env = dict(os.environ, HAPTICOP_ECAT_CONTROL=str(box.control))
            env[TRUTH_ENV] = str(box.truth)
            try:
                code = subprocess.call(command, env=env)
            except FileNotFoundError:
                typer.echo(f"error: no such command: {command[0]}", err=True)
                code = 127
            except KeyboardInterrupt:
                code = 130
    except (OSError, RuntimeError) as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(1)
    raise typer.Exit(code)


@ethercat.command("emulate")
def emulate(
    interface: str = typer.Argument(..., help="the interface the master's frames arrive on"),
    control: Path | None = typer.Option(None, help="Unix socket for faults and status"),
    truth: Path | None = typer.Option(None, help="file the robot's true pose is published to"),
    seed: int = typer.Option(0),
) -> None:
    """Run the emulated segment on an existing interface until Ctrl+C (root)."""
    from hapticop.devices.ethercat.__main__ import main

    args = [interface, "--seed", str(seed)]
    if control:
        args += ["--control", str(control)]
    if truth:
        args += ["--truth", str(truth)]
    raise typer.Exit(main(args))


@ethercat.command("fault")
def fault(
    op: str = typer.Argument(..., help="lose, restore (power), cut, reconnect (the cable into --slave), al_error, "
                                       "trip_watchdog, late, physics, status"),
    slave: int | None = typer.Option(None, help="bus position, 0-based (0 EK1100, 2/3/5/6 the wheels)"),
    code: str | None = typer.Option(None, help="AL status code for al_error, e.g. 0x001B"),
    delay_us: int | None = typer.Option(None, help="late: how late each reply is"),
    frames: int | None = typer.Option(None, help="late: how many replies"),
    control: Path | None = typer.Option(None, envvar="HAPTICOP_ECAT_CONTROL", help="the emulator's control socket"),
) -> None:
    """Inject a fault into a running emulator (or print its status)."""
    from hapticop.devices.ethercat.emulator.server import control as send

    if control is None:
        typer.echo("error: no control socket: pass --control or run inside `hapticop ethercat sandbox`", err=True)
        raise typer.Exit(2)
    request: dict = {"op": op}
    for key, value in (("slave", slave), ("delay_us", delay_us), ("frames", frames)):
        if value is not None:
            request[key] = value
    if code is not None:
        request["code"] = int(code, 0)
    try:
        answer = send(control, request)
    except OSError as error:
        typer.echo(f"error: cannot reach the emulator at {control}: {error}", err=True)
        raise typer.Exit(1)
    typer.echo(json.dumps(answer, indent=2))
    raise typer.Exit(0 if answer.get("ok") else 1)
