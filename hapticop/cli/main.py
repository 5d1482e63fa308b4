"""The `hapticop` command line."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from enum import Enum
from pathlib import Path

import typer

from hapticop.cli.helptext import plain_help
from hapticop.composition.diagnostics import Report, reports_to_json
from hapticop.validation import validate_path
from hapticop.validation.reachability import DEFAULT_STATE_LIMIT

app = typer.Typer(
    help="Declarative real-time dataflow for haptic teleoperation.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

SYSTEMS_DIR = Path("systems")
plain_help()


def _version(asked: bool) -> None:
    if asked:
        from hapticop import __version__

        typer.echo(f"hapticop {__version__}")
        raise typer.Exit()


@app.callback()
def _options(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                          help="print hapticop's version and exit")) -> None:
    """Declarative real-time dataflow for haptic teleoperation."""

from hapticop.cli.catalogue import blocks as _blocks  # noqa: E402
from hapticop.cli.devices import devices as _devices  # noqa: E402
from hapticop.cli.devices import falcon as _falcon  # noqa: E402
from hapticop.cli.devices import lidar as _lidar  # noqa: E402
from hapticop.cli.docpages import docs as _docs  # noqa: E402
from hapticop.cli.ethercat import ethercat as _ethercat  # noqa: E402
from hapticop.cli.new import new as _new  # noqa: E402
from hapticop.cli.recordings import info as _info  # noqa: E402
from hapticop.cli.recordings import plot as _plot  # noqa: E402
from hapticop.cli.recordings import recover as _recover  # noqa: E402
from hapticop.cli.recordings import replay as _replay  # noqa: E402
from hapticop.cli.recordings import report as _report  # noqa: E402

app.add_typer(_lidar, name="lidar")
app.add_typer(_falcon, name="falcon")
app.command("devices")(_devices)
app.add_typer(_ethercat, name="ethercat")
app.command("blocks")(_blocks)
app.command("new")(_new)
app.command("info")(_info)
app.command("recover")(_recover)
app.command("plot")(_plot)
app.command("replay")(_replay)
app.command("report")(_report)
app.command("docs")(_docs)


class OutputFormat(str, Enum):
    text = "text"
    json = "json"


class GraphFormat(str, Enum):
    svg = "svg"
    png = "png"
    dot = "dot"


def _system_files() -> list[Path]:
    return sorted(p for p in SYSTEMS_DIR.glob("*.y*ml") if p.suffix in (".yaml", ".yml"))


@app.command()
def validate(
    files: list[Path] | None = typer.Argument(None, help="composition files (default: every file in systems/)"),
    format: OutputFormat = typer.Option(OutputFormat.text, "--format", help="text for people, json for editors and CI"),
    state_limit: int = typer.Option(DEFAULT_STATE_LIMIT, min=100, help="markings to explore per Petri net"),
    strict: bool = typer.Option(False, help="treat warnings as errors"),
    import_blocks: bool = typer.Option(
        False, "--import-blocks",
        help="import the modules of third-party blocks (running their code) to check their parameters"),
) -> None:
    """Check composition files without running anything; exit 1 on any error."""
    from hapticop.blocks.registry import blocks_not_imported

    paths = list(files or _system_files())
    if not paths:
        typer.echo(f"no composition files given and none in {SYSTEMS_DIR}/", err=True)
        raise typer.Exit(2)
    with contextlib.nullcontext() if import_blocks else blocks_not_imported():
        reports: list[Report] = [validate_path(p, state_limit).report for p in paths]
    if format is OutputFormat.json:
        typer.echo(reports_to_json(reports))
    else:
        for report in reports:
            for diagnostic in report.sorted():
                typer.echo(diagnostic.to_text())
            status = "ok" if report.ok else "FAILED"
            typer.echo(f"{report.file}: {status} ({_count(len(report.errors), 'error')}, "
                       f"{_count(len(report.warnings), 'warning')})")
    failed = any(not r.ok or (strict and r.warnings) for r in reports)
    raise typer.Exit(1 if failed else 0)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


class ClockKind(str, Enum):
    realtime = "realtime"
    virtual = "virtual"


def _duration(text: str | None, option: str) -> int | None:
    if text is None:
        return None
    from hapticop.composition.units import parse_duration_ns

    try:
        return parse_duration_ns(text, rates=False)
    except ValueError as error:
        raise typer.BadParameter(str(error), param_hint=option) from None


def _valid_or_exit(file: Path, refusal: str):
    """Validate, print every finding, and stop with status 1 on errors."""
    validated = validate_path(file)
    for diagnostic in validated.report.sorted():
        typer.echo(diagnostic.to_text(), err=True)
    if not validated.report.ok:
        typer.echo(f"{file}: {refusal}: {_count(len(validated.report.errors), 'error')}", err=True)
        raise typer.Exit(1)
    return validated


@app.command()
def compose(
    file: Path = typer.Argument(..., help="composition file"),
    clock: ClockKind = typer.Option(ClockKind.realtime, "--clock",
                                    help="realtime, or virtual: simulated time, as fast as the CPU allows"),
    duration: str | None = typer.Option(None, help="stop after this long (e.g. 30s); default: until Ctrl+C"),
    seed: int = typer.Option(0, help="seed of every activity's random generator"),
    run_dir: Path | None = typer.Option(
        None, help="logs and timing.json (default: a new directory under /dev/shm/hapticop-UID, yours alone)"),
    shutdown_timeout: str = typer.Option("5s", help="how long coordination may take to shut down before it is forced"),
    control: str | None = typer.Option(
        None, help="control socket name or path for patch/status (default: the composition's name)"),
    check: bool = typer.Option(False, "--check", help="exit 1 when the run's results miss a target (for CI)"),
    group_readable: bool = typer.Option(
        False, "--group-readable", envvar="HAPTICOP_GROUP_READABLE",
        help="let your group read the run's logs and results (directories 0750, files 0640; default: yours alone)"),
    record: str | None = typer.Option(
        None, "--record", metavar="[FILE]",
        help="record the streams to an MCAP file (default: NAME.mcap in the run directory); every stream "
             "unless the file's 'record:' chooses"),
    host: str | None = typer.Option(
        None, help="with 'hosts:' in the file, run this host's side only (default: every host here, side by side)"),
    view: str | None = typer.Option(
        None, "--view", metavar="[PORT]",
        help="show the run live in Foxglove (a Foxglove WebSocket connection to this port, default 8765): the "
             "recorded streams, or every stream, with the scan, frames, force arrow, logs and loop timing"),
    view_host: str = typer.Option("127.0.0.1", help="where --view listens (default: this machine only)"),
    view_rate: float = typer.Option(30.0, help="most messages a second --view sends per channel"),
    view_tls_cert: Path | None = typer.Option(None, help="a PEM certificate: --view speaks wss:// only (with "
                                                         "--view-tls-key)"),
    view_tls_key: Path | None = typer.Option(None, help="the certificate's PEM PKCS#8 private key"),
) -> None:
    """Validate a composition, then run it; Ctrl+C shuts it down (twice forces)."""
    from rich.console import Console

    from hapticop.runtime.report import print_recording, print_results, print_timing
    from hapticop.runtime.system import RunOptions, run_system

    live = None if view is None else _live_options(view, view_host, view_rate, view_tls_cert, view_tls_key)
    validated = _valid_or_exit(file, "not started")
    if validated.hosts:
        validated = _one_host(validated, file, host, clock, run_dir, group_readable, sys.argv)
    # What the run writes (logs, results, recordings) is its owner's alone, or also their group's
    # to read; its child processes inherit the mask.
    os.umask(0o027 if group_readable else 0o077)
    options = RunOptions(clock=clock.value, duration_ns=_duration(duration, "--duration"), seed=seed,
                         run_dir=run_dir, shutdown_timeout_ns=_duration(shutdown_timeout, "--shutdown-timeout"),
                         control=control, group_readable=group_readable, record=record, view=live)
    console = Console(stderr=True)
    if not console.is_terminal:
        console.width = 160  # a log or a pipe: no need to wrap the tables

    def announce(system) -> None:
        console.print(f"[bold]{system.composition.name or file}[/]: running ({clock.value} clock); "
                      f"logs in {system.run_dir}")
        if console.is_terminal:
            from hapticop.runtime.report import progress_line

            threading.Thread(target=progress_line, args=(system, console), daemon=True).start()

    result = run_system(validated, options, on_start=announce)
    print_timing(result.timing, console, result.virtual)
    print_results(result.outcome.run_dir, console)
    if result.recording is not None:
        print_recording(result.recording, console)
    for reason in result.outcome.reasons:
        console.print(f"[red]{reason}[/]")
    status = int(result.outcome.status)
    if check and status == 0:
        from hapticop.runtime.report import missed_targets

        missed = missed_targets(result.outcome.run_dir)
        for name in missed:
            console.print(f"[red]target missed: {name}[/]")
        status = 1 if missed else 0
    console.print(f"exit: {result.outcome.status.name.lower() if status == int(result.outcome.status) else 'failure'}"
                  f" ({status})")
    raise typer.Exit(status)


def _one_host(validated, file: Path, host: str | None, clock: ClockKind, run_dir: Path | None,
              group_readable: bool, argv: list[str]):
    """The side of a composition on several hosts that `--host` names; without it, every side here
    (each a `compose --host` child), and this process exits with their status."""
    if clock is not ClockKind.realtime:
        typer.echo(f"{file}: a composition with hosts runs in real time (its bridges cross a real network)", err=True)
        raise typer.Exit(2)
    if host is None:
        from hapticop.cli.hosts import run_every_host
        from hapticop.runtime.rundirs import new_run_directory, private_directory

        parent = private_directory(run_dir) if run_dir else new_run_directory(
            validated.composition.name or file.stem, group=group_readable)
        typer.echo(f"{file}: hosts {', '.join(validated.hosts)} beside each other; runs in {parent}", err=True)
        raise typer.Exit(run_every_host(file, list(validated.hosts), parent, _passed_on(argv)))
    if host not in validated.hosts:
        typer.echo(f"{file}: no host '{host}' (hosts: {', '.join(validated.hosts)})", err=True)
        raise typer.Exit(2)
    return validated.hosts[host]


def _passed_on(argv: list[str]) -> list[str]:
    """The compose options a host's child takes as they were given (not the file, --host or --run-dir)."""
    out, skip = [], False
    for arg in argv[argv.index("compose") + 2 if "compose" in argv else 0:]:
        if skip:
            skip = False
        elif arg in ("--run-dir", "--host"):
            skip = True
        elif not arg.startswith(("--run-dir=", "--host=")):
            out.append(arg)
    return out
@app.command("view")
def view_running(
    system: str = typer.Argument(..., help="the running system's name (or its control socket's path)"),
    port: int = typer.Option(8765, help="the port Foxglove connects to (Foxglove WebSocket)"),
    host: str = typer.Option("127.0.0.1", help="where to listen (default: this machine only)"),
    rate: float = typer.Option(30.0, help="most messages a second per channel"),
    tls_cert: Path | None = typer.Option(None, help="a PEM certificate: speak wss:// only (with --tls-key)"),
    tls_key: Path | None = typer.Option(None, help="the certificate's PEM PKCS#8 private key"),
) -> None:
    """Show a running system live in Foxglove, from a process of its own: every stream's newest
    sample, the scan, frames and force arrow, the loops' timing and the log; Ctrl+C stops."""
    from hapticop.runtime.viewer import Attachment, view

    options = _live_options(str(port), host, rate, tls_cert, tls_key)
    answer = _ask(system, {"op": "attach"})
    if not answer.get("ok"):
        typer.echo(f"hapticop: {system}: {answer.get('error')}", err=True)
        raise typer.Exit(1)
    stop = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        summary = view(Attachment(**answer["attach"]), options, lambda line: typer.echo(f"{line}; Ctrl+C stops",
                                                                                        err=True), stop.is_set)
    finally:
        signal.signal(signal.SIGINT, previous)
    typer.echo(f"{summary['view']['sent']} messages sent", err=True)


def _live_options(port: str, host: str, rate_hz: float, tls_cert: Path | None = None, tls_key: Path | None = None):
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


def _ask(system: str, message: dict) -> dict:
    from hapticop.runtime.control import ControlError, request

    try:
        return request(system, message, timeout=30.0)
    except ControlError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(2) from None


@app.command()
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
    reply = _ask(system, {"op": "patch", "text": text, "file": str(file), "dry_run": dry_run})
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


@app.command()
def status(
    system: str = typer.Argument(..., help="the running system's name (or its control socket path)"),
    json_output: bool = typer.Option(False, "--json", help="the whole status as JSON"),
) -> None:
    """LCSM states, selected schedules, flags, markings and timing of a running system."""
    import json

    reply = _ask(system, {"op": "status"})
    if not reply.get("ok"):
        typer.echo(f"error: {reply.get('error')}", err=True)
        raise typer.Exit(1)
    state = reply["status"]
    if json_output:
        typer.echo(json.dumps(state, indent=2))
        return
    typer.echo(f"{state['name']}: {state['clock']} clock, up {state['uptime_s']:.1f} s")
    for name, t in state["threads"].items():
        timing = state["timing"]["threads"][name]
        failed = f" FAILED: {t['failed']}" if t["failed"] else ""
        typer.echo(f"  thread {name}: {t['state']}, schedule {t['schedule']}, {timing['cycles']} cycles, "
                   f"{timing['missed_deadlines']} missed{failed}")
    for name, a in state["activities"].items():
        failed = f" FAILED: {a['failed']}" if a["failed"] else ""
        waiting = f", waiting for {a['waiting_for']}" if a.get("waiting_for") else ""
        typer.echo(f"  activity {name}: {a['state']}{waiting}{failed}")
    for net, marking in state["markings"].items():
        typer.echo(f"  net {net}: {marking}")
    if state.get("modes") is not None:
        typer.echo(f"  modes holding: {', '.join(state['modes']) or 'none'}")
    typer.echo(f"  flags set: {', '.join(state['flags'])}")
    for name, link in state.get("links", {}).items():
        health = "lost" if link["lost"] else "degraded" if link["degraded"] else "up" if link["up"] else "waiting"
        error = link["offset_error_ms"]
        within = f" (within {error:.3f})" if error is not None else " (not yet measured)"
        typer.echo(f"  link {name} to {', '.join(link['peers'])}: {health}, round trip {link['rtt_ms']:.2f} ms, "
                   f"jitter {link['jitter_ms']:.2f} ms, loss {link['loss']:.1%}, clock offset "
                   f"{link['offset_ms']:+.3f} ms{within}")


@app.command()
def expand(file: Path = typer.Argument(..., help="composition file")) -> None:
    """Print a composition as YAML with its standard coordination written out as nets and flag maps;
    exit 1 if the file has errors."""
    from hapticop.composition.documents import dump
    from hapticop.composition.standard import expanded_tree

    validated = validate_path(file)
    for diagnostic in validated.report.sorted():
        typer.echo(diagnostic.to_text(), err=True)
    if not validated.report.ok:
        typer.echo(f"{file}: not expanded: {_count(len(validated.report.errors), 'error')}", err=True)
        raise typer.Exit(1)
    typer.echo(dump(expanded_tree(validated.source.tree, validated.graph.loaded.expansion)), nl=False)


@app.command()
def graph(
    file: Path = typer.Argument(..., help="composition file"),
    view: str = typer.Option("dataflow", "--view", metavar="VIEW",
                             help="dataflow (threads, activities, streams), nets (every net and its flags), "
                                  "the name of one net, or all"),
    output: Path | None = typer.Option(None, "-o", "--output", metavar="PATH",
                                       help="where to write (default: FILE-VIEW.FORMAT in the current directory)"),
    format: GraphFormat = typer.Option(GraphFormat.svg, "--format", help="svg, png, or dot text"),
) -> None:
    """Draw a composition: by default its dataflow; its nets and flag maps with --view nets."""
    from hapticop.cli.render import RenderError, drawing, render, to_dot

    validated = validate_path(file)
    if validated.graph is None or validated.graph.loaded.composition is None:
        for diagnostic in validated.report.sorted():
            typer.echo(diagnostic.to_text(), err=True)
        typer.echo(f"{file}: cannot draw a file that does not load", err=True)
        raise typer.Exit(1)
    errors = len(validated.report.errors)
    if errors:
        typer.echo(f"{file}: note: the file has {_count(errors, 'error')}; drawing what loaded", err=True)
    try:
        picture = drawing(validated.graph, view)
    except RenderError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(2) from None
    if format is GraphFormat.dot and output is None:
        typer.echo(to_dot(picture), nl=False)
        return
    target = output or Path.cwd() / f"{file.stem}-{view}.{format.value}"
    if format is GraphFormat.dot:
        target.write_text(to_dot(picture))
        typer.echo(f"wrote {target}")
        return
    try:
        used = render(picture, target, format.value)
    except RenderError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"wrote {target}" + (" (without graphviz: a simple layout)" if used == "layered" else ""))


@app.command()
def bench(
    file: Path = typer.Argument(Path("systems/bench.yaml"), help="composition to measure"),
    duration: str = typer.Option("30s", help="how long each condition runs"),
    out: Path | None = typer.Option(None, help="report directory (default: ./hapticop-bench-DATE)"),
    load: bool = typer.Option(True, help="also run under load on every core"),
    repeat: int = typer.Option(1, min=1, help="rounds of every condition: the report gives each figure's spread"),
) -> None:
    """Measure a composition idle and under load beside cyclictest; write report.md and latency.png."""
    import time

    from hapticop.benchmark import report, runner

    seconds = _duration(duration, "--duration") / 1e9
    _valid_or_exit(file, "not measured")
    out = out or Path(f"hapticop-bench-{time.strftime('%Y%m%d-%H%M%S')}")
    out.mkdir(parents=True, exist_ok=True)
    conditions = ("idle", "loaded") if load else ("idle",)
    try:
        result = runner.run(str(file), seconds, out, conditions, say=lambda text: typer.echo(text, err=True),
                            repeat=repeat)
    except RuntimeError as error:
        typer.echo(f"bench failed: {error}", err=True)
        raise typer.Exit(1) from None
    text = report.markdown(result)
    (out / "report.md").write_text(text)
    picture = report.histogram_png(result, out / "latency.png")
    typer.echo(text)
    typer.echo(f"report: {out / 'report.md'}" + (f", histogram: {picture}" if picture else
                                                  " (no histogram: pip install matplotlib)"), err=True)


@app.command()
def schema(
    check: bool = typer.Option(False, help="exit 1 if schemas/composition.schema.json is not current"),
    write: bool = typer.Option(False, help="regenerate schemas/composition.schema.json"),
) -> None:
    """Print (or check, or write) the JSON Schema of composition files."""
    from hapticop.composition.schema import SCHEMA_FILE, schema_text

    text = schema_text()
    if check:
        current = SCHEMA_FILE.read_text() if SCHEMA_FILE.exists() else ""
        if current != text:
            typer.echo(f"{SCHEMA_FILE} is out of date; run `hapticop schema --write`", err=True)
            raise typer.Exit(1)
        typer.echo(f"{SCHEMA_FILE} is current")
    elif write:
        SCHEMA_FILE.parent.mkdir(parents=True, exist_ok=True)
        SCHEMA_FILE.write_text(text)
        typer.echo(f"wrote {SCHEMA_FILE}")
    else:
        typer.echo(text, nl=False)


OPTIONAL_VALUES = ("--record", "--view")  # options whose value may be left out: `--record`, `--view 9000`


def bare_options(argv: list[str]) -> list[str]:
    """`--record` or `--view` with no value (last, before another option, or before the composition
    file) gets the empty value that means "the default" (file, port): the parser has no optional values."""
    out = []
    for index, arg in enumerate(argv):
        out.append(arg)
        following = argv[index + 1] if index + 1 < len(argv) else None
        if arg in OPTIONAL_VALUES and (following is None or following.startswith("-")
                                       or following.endswith((".yaml", ".yml"))):
            out.append("")
    return out


def main() -> None:
    """Entry point: no Python traceback reaches the user unless HAPTICOP_DEBUG is set."""
    from hapticop.runtime.control import ControlError
    from hapticop.runtime.preflight import DevicesMissing
    from hapticop.runtime.rundirs import RunDirectoryError
    from hapticop.runtime.supervisor import ExitStatus, ForcedExit

    try:
        app(args=bare_options(sys.argv[1:]))
    except ForcedExit as forced:
        print("hapticop: interrupted again: left at once, without a clean shutdown", file=sys.stderr)
        sys.exit(int(forced.args[0]))
    except KeyboardInterrupt:  # before the run's own handler (validating, starting): nothing was left running
        print("hapticop: interrupted", file=sys.stderr)
        sys.exit(130)
    except (RunDirectoryError, ControlError) as error:  # a directory not safely ours, a socket name that is none
        print(f"hapticop: {error}", file=sys.stderr)
        sys.exit(2)
    except DevicesMissing as error:  # the hardware is not there: nothing was started
        print(f"hapticop: {error}", file=sys.stderr)
        sys.exit(int(ExitStatus.UNAVAILABLE))
    except Exception as error:  # noqa: BLE001 - the last line of defence for the user interface
        if os.environ.get("HAPTICOP_DEBUG"):
            raise
        print(f"hapticop: internal error: {type(error).__name__}: {error}\n"
              "  set HAPTICOP_DEBUG=1 to see where, and please report it", file=sys.stderr)
        sys.exit(3)

