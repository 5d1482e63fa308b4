"""The `hapticop` command line."""

from __future__ import annotations

import contextlib
import os
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
from hapticop.cli.experiments import experiment as _experiment  # noqa: E402
from hapticop.cli.hosts import hosts as _hosts  # noqa: E402
from hapticop.cli.new import new as _new  # noqa: E402
from hapticop.cli.recordings import info as _info  # noqa: E402
from hapticop.cli.recordings import plot as _plot  # noqa: E402
from hapticop.cli.recordings import recover as _recover  # noqa: E402
from hapticop.cli.recordings import replay as _replay  # noqa: E402
from hapticop.cli.recordings import report as _report  # noqa: E402
from hapticop.cli.running import live_options  # noqa: E402
from hapticop.cli.running import patch as _patch  # noqa: E402
from hapticop.cli.running import status as _status  # noqa: E402
from hapticop.cli.running import view as _view  # noqa: E402

app.add_typer(_lidar, name="lidar")
app.add_typer(_falcon, name="falcon")
app.command("devices")(_devices)
app.add_typer(_ethercat, name="ethercat")
app.add_typer(_hosts, name="hosts")
app.add_typer(_experiment, name="experiment")
app.command("blocks")(_blocks)
app.command("new")(_new)
app.command("info")(_info)
app.command("recover")(_recover)
app.command("plot")(_plot)
app.command("replay")(_replay)
app.command("report")(_report)
app.command("docs")(_docs)


def _validate_one(path: Path, state_limit: int) -> Report:
    """A composition, or an experiment file (its factors checked against its composition)."""
    from hapticop.experiment.checks import is_experiment, load

    return load(path).report if is_experiment(path) else validate_path(path, state_limit).report


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
        reports: list[Report] = [_validate_one(p, state_limit) for p in paths]
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
    check: bool = typer.Option(False, "--check",
                               help="exit 1 when the run's results miss a target (for CI; without it the last line "
                                    "says which were missed and the status stays 0)"),
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

    from hapticop.cli.report import closing_line, missed_targets, print_recording, print_results, print_timing
    from hapticop.runtime.system import RunOptions, run_system

    live = None if view is None else live_options(view, view_host, view_rate, view_tls_cert, view_tls_key)
    validated = _valid_or_exit(file, "not started")
    _say_if_insecure(validated, file)
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
            from hapticop.cli.report import progress_line

            threading.Thread(target=progress_line, args=(system, console), daemon=True).start()

    result = run_system(validated, options, on_start=announce)
    print_timing(result.timing, console, result.virtual)
    print_results(result.outcome.run_dir, console)
    if result.recording is not None:
        print_recording(result.recording, console)
    for reason in result.outcome.reasons:
        console.print(f"[red]{reason}[/]")
    missed = missed_targets(result.outcome.run_dir)
    for name in missed:
        console.print(f"[red]target missed: {name}[/]")
    status, line = closing_line(int(result.outcome.status), result.outcome.status.name.lower(), missed, check)
    console.print(f"[red]{line}[/]" if status or missed else line, highlight=False, soft_wrap=True)  # one line
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
        from hapticop.rundirs import new_run_directory, private_directory

        parent = private_directory(run_dir) if run_dir else new_run_directory(
            validated.composition.name or file.stem, group=group_readable)
        typer.echo(f"{file}: hosts {', '.join(validated.hosts)} beside each other; runs in {parent}", err=True)
        raise typer.Exit(run_every_host(file, list(validated.hosts), parent, _passed_on(argv)))
    if host not in validated.hosts:
        typer.echo(f"{file}: no host '{host}' (hosts: {', '.join(validated.hosts)})", err=True)
        raise typer.Exit(2)
    return validated.hosts[host]


def _say_if_insecure(validated, file: Path) -> None:
    """A run on an insecure link says so before anything else (docs/security.md)."""
    if validated.hosts and validated.graph.loaded.composition.security.insecure:
        typer.echo(f"{file}: INSECURE LINK ('security: {{insecure: true}}'): anyone who reaches these hosts may "
                   "join, read every stream and drive the robot", err=True)


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
app.command("view")(_view)  # here, so that `hapticop --help` lists them after compose, as it always did
app.command("patch")(_patch)
app.command("status")(_status)


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
                                       help="where to write, '-' for standard output (default: FILE-VIEW.FORMAT in the "
                                            "current directory)"),
    format: GraphFormat = typer.Option(GraphFormat.svg, "--format", help="svg, png, or dot text"),
) -> None:
    """Draw a composition: by default its dataflow; its nets and flag maps with --view nets."""
    from hapticop.cli.outputs import is_stdout, say_wrote, written
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
    if format is GraphFormat.dot and (output is None or is_stdout(output)):
        typer.echo(to_dot(picture), nl=False)
        return
    target = output or Path.cwd() / f"{file.stem}-{view}.{format.value}"
    if format is GraphFormat.dot:
        target.write_text(to_dot(picture))
        typer.echo(say_wrote(target))
        return
    try:
        with written(target, f".{format.value}") as path:
            used = render(picture, path, format.value)
    except RenderError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(1) from None
    typer.echo(say_wrote(target, " (without graphviz: a layered layout)" if used == "layered" else ""),
               err=is_stdout(target))


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
    check: bool = typer.Option(False, help="exit 1 if the files in schemas/ are not current"),
    write: bool = typer.Option(False, help="regenerate schemas/composition.schema.json and experiment.schema.json"),
) -> None:
    """Print (or check, or write) the JSON Schema of composition files (and, with --check/--write, of
    experiment files)."""
    from hapticop.composition import schema as composition
    from hapticop.experiment import schema as experiment

    pairs = [(composition.SCHEMA_FILE, composition.schema_text()), (experiment.SCHEMA_FILE, experiment.schema_text())]
    if check:
        for file, text in pairs:
            current = file.read_text() if file.exists() else ""
            if current != text:
                typer.echo(f"{file} is out of date; run `hapticop schema --write`", err=True)
                raise typer.Exit(1)
            typer.echo(f"{file} is current")
    elif write:
        for file, text in pairs:
            file.parent.mkdir(parents=True, exist_ok=True)
            file.write_text(text)
            typer.echo(f"wrote {file}")
    else:
        typer.echo(pairs[0][1], nl=False)


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
    from hapticop.control.address import ControlError
    from hapticop.rundirs import RunDirectoryError
    from hapticop.runtime.preflight import DevicesMissing
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

