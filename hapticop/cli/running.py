"""`hapticop view`, `patch` and `status`: the commands that talk to a running system over its control socket."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import typer


def view(
    system: str = typer.Argument(..., help="the running system's name (or its control socket's path)"),
    port: int = typer.Option(8765, help="the port Foxglove connects to (Foxglove WebSocket)"),
    host: str = typer.Option("127.0.0.1", help="where to listen (default: this machine only)"),
    rate: float = typer.Option(30.0, help="most messages a second per channel"),
    tls_cert: Path | None = typer.Option(None, help="a PEM certificate: speak wss:// only (with --tls-key)"),
    tls_key: Path | None = typer.Option(None, help="the certificate's PEM PKCS#8 private key"),
) -> None:
    """Show a running system live in Foxglove, from a process of its own: every stream's newest
    sample, the scan, frames and force arrow, the loops' timing and the log; Ctrl+C stops."""
    from hapticop.observe.viewer import Attachment, view
    from hapticop.recording.live import LiveViewUnavailable

    options = live_options(str(port), host, rate, tls_cert, tls_key)
    answer = ask(system, {"op": "attach"})
    if not answer.get("ok"):
        typer.echo(f"hapticop: {system}: {answer.get('error')}", err=True)
        raise typer.Exit(1)
    stop = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        summary = view(Attachment(**answer["attach"]), options, lambda line: typer.echo(f"{line}; Ctrl+C stops",
                                                                                        err=True), stop.is_set)
    except LiveViewUnavailable as unavailable:  # a port taken, a run directory it may not write its token in
        typer.echo(f"hapticop: {unavailable}", err=True)
        raise typer.Exit(2) from None
    finally:
        signal.signal(signal.SIGINT, previous)
    typer.echo(f"{summary['view']['sent']} messages sent", err=True)


def live_options(port: str, host: str, rate_hz: float, tls_cert: Path | None = None, tls_key: Path | None = None):
    """`--view`'s options, or a one-line error (no foxglove-sdk, a port that is no number, an
    unreadable TLS identity); says at start who can watch when it is more than this machine."""
    from hapticop.recording.live import (
        DEFAULT_PORT,
        LiveOptions,
        LiveViewUnavailable,
        exposure,
        read_identity,
        require_sdk,
    )

    if (tls_cert is None) != (tls_key is None):
        raise typer.BadParameter("give both a TLS certificate and its key, or neither", param_hint="TLS")
    try:
        require_sdk()
        number = int(port) if port else DEFAULT_PORT
    except LiveViewUnavailable as missing:
        typer.echo(f"hapticop: {missing}", err=True)
        raise typer.Exit(2) from None
    except ValueError as error:
        raise typer.BadParameter(str(error) if port.isdigit() or not port else f"not a port: {port!r}",
                                 param_hint="--view") from None
    try:
        options = LiveOptions(host, number, rate_hz, str(tls_cert) if tls_cert else None,
                              str(tls_key) if tls_key else None)
        read_identity(options)
    except LiveViewUnavailable as missing:
        typer.echo(f"hapticop: {missing}", err=True)
        raise typer.Exit(2) from None
    except ValueError as error:
        raise typer.BadParameter(str(error), param_hint="--view") from None
    warning = exposure(options)
    if warning:
        typer.echo(f"hapticop: {warning}", err=True)
    return options


def ask(system: str, message: dict) -> dict:
    from hapticop.control.address import ControlError
    from hapticop.control.client import request

    try:
        return request(system, message, timeout=30.0)
    except ControlError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(2) from None


def patch(
    system: str = typer.Argument(..., help="the running system's name (or its control socket path)"),
    file: Path = typer.Argument(..., help="a JSON Patch (a YAML list of operations) or a merge patch (a YAML mapping)"),
    dry_run: bool = typer.Option(False, "--dry-run", help="validate and show the diff; change nothing"),
) -> None:
    """Change a running system: validated whole, applied at a cycle boundary, or refused."""
    from hapticop.composition.yamlsource import SourceError, read_text

    try:
        text = read_text(file, "a patch")
    except SourceError as error:
        typer.echo(error.diagnostic.to_text(), err=True)
        raise typer.Exit(2) from None
    reply = ask(system, {"op": "patch", "text": text, "file": str(file), "dry_run": dry_run})
    if not reply.get("ok"):
        from hapticop.composition.diagnostics import Diagnostic, Severity

        for item in reply.get("diagnostics", []):
            item = {**item, "severity": Severity(item["severity"]), "path": tuple(item["path"])}
            typer.echo(Diagnostic(**item).to_text(), err=True)
        typer.echo(f"{file}: {reply.get('error', 'refused')}; the system runs on unchanged", err=True)
        raise typer.Exit(1)
    typer.echo(reply["diff"], nl=False)
    for line in reply["changes"]:
        typer.echo(f"  {line}")
    typer.echo("applied" if reply.get("applied") else "dry run: nothing applied")


def status(
    system: str = typer.Argument(..., help="the running system's name (or its control socket path)"),
    json_output: bool = typer.Option(False, "--json", help="the whole status as JSON"),
    params: list[str] = typer.Option(None, "--params", help="also each named activity's parameters as it runs "
                                     "them (a mode's values included); repeat it for more; 'all' for every one"),
) -> None:
    """LCSM states, selected schedules, flags, markings, timing and parameters of a running system."""
    import json
    import textwrap

    from hapticop.composition.documents import dump

    reply = ask(system, {"op": "status"})
    if not reply.get("ok"):
        typer.echo(f"error: {reply.get('error')}", err=True)
        raise typer.Exit(1)
    state = reply["status"]
    if json_output:
        typer.echo(json.dumps(state, indent=2))
        return
    typer.echo(f"{state['name']}: {state['clock']} clock, up {state['uptime_s']:.1f} s, "
               f"description revision {state.get('revision', 0)}")
    for name, t in state["threads"].items():
        timing = state["timing"]["threads"][name]
        failed = f" FAILED: {t['failed']}" if t["failed"] else ""
        typer.echo(f"  thread {name}: {t['state']}, schedule {t['schedule']}, {timing['cycles']} cycles, "
                   f"{timing['missed_deadlines']} missed{failed}")
    for name, a in state["activities"].items():
        failed = f" FAILED: {a['failed']}" if a["failed"] else ""
        waiting = f", waiting for {a['waiting_for']}" if a.get("waiting_for") else ""
        typer.echo(f"  activity {name}: {a['state']}{waiting}{failed}")
        if params and ("all" in params or name in params):
            typer.echo(textwrap.indent(dump(a.get("params") or {}), "      "), nl=False)
    unknown = sorted(set(params or ()) - set(state["activities"]) - {"all"})
    if unknown:
        typer.echo(f"error: no activity {', '.join(repr(u) for u in unknown)} in '{state['name']}'", err=True)
        raise typer.Exit(1)
    for net, marking in state["markings"].items():
        typer.echo(f"  net {net}: {marking}")
    if state.get("modes") is not None:
        typer.echo(f"  modes holding: {', '.join(state['modes']) or 'none'}")
    typer.echo(f"  flags set: {', '.join(state['flags'])}")
    for name, link in state.get("links", {}).items():  # from its figures' streams (`bridge_rtt`, ...)
        peers = f"  link {name} to {', '.join(link['peers'])}: {link['health']}"
        if "sessions" not in link:  # not all told yet
            typer.echo(f"{peers}, no figures yet")
            continue
        error = link["offset_error_ms"]
        within = f" (within {error:.3f})" if error is not None else " (not yet measured)"
        typer.echo(f"{peers}, round trip {link['rtt_ms']:.2f} ms, jitter {link['jitter_ms']:.2f} ms, "
                   f"loss {link['loss']:.1%}, clock offset {link['offset_ms']:+.3f} ms{within}, "
                   f"{link['refused']} refused")
