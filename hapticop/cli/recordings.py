"""`hapticop info`, `recover` and `plot`: looking at a run's MCAP recording."""

from __future__ import annotations

import errno
from pathlib import Path

import typer


def _fail(message: str, code: int = 1) -> typer.Exit:
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)


def info(
    file: Path = typer.Argument(..., help="a recording (RUN.mcap)"),
    composition: bool = typer.Option(False, "--composition", help="also print the composition the run used"),
) -> None:
    """Channels, counts, rates and drops of a recording, and the run it came from."""
    from hapticop.recording.reading import RecordingError, contents

    try:
        found = contents(file)
    except RecordingError as error:
        raise _fail(str(error)) from None
    run = found.metadata.get("hapticop.run", {})
    drops = found.drops()
    typer.echo(f"{file}: {run.get('composition', '?')} from {run.get('file', '?')}, {found.duration_s:.3f} s "
               f"of log time on the {run.get('clock', '?')} clock")
    typer.echo(f"  {'channel':<34} {'messages':>9} {'rate Hz':>9} {'nominal':>8} {'dropped':>8}  type")
    for channel in sorted(found.channels, key=lambda c: c.topic):
        measured = channel.count / found.duration_s if found.duration_s > 0 else 0.0
        stream = channel.stream
        nominal = f"{stream.rate_hz / stream.every:g}" if stream else ""
        dropped = str(drops.get(stream.name, "?")) if stream else ""
        kind = f"{stream.dtype}{list(stream.shape)} [{stream.unit}]" if stream else channel.schema
        typer.echo(f"  {channel.topic:<34} {channel.count:>9} {measured:>9.1f} {nominal:>8} {dropped:>8}  {kind}")
    if "hapticop.drops" not in found.metadata:
        typer.echo("  (no drop counts: the recording was recovered from a run that did not finish it)")
    elif any(drops.values()):
        typer.echo(f"  {sum(drops.values())} samples lost: the recorder fell a whole ring behind "
                   "(a larger 'record.depth' holds more)")
    typer.echo(f"  attachments: {', '.join(found.attachments) or 'none'}")
    if composition and "composition.yaml" in found.attachments:
        typer.echo(found.attachments["composition.yaml"].decode(), nl=False)


def recover(
    file: Path = typer.Argument(..., help="what a killed run left (RUN.mcap.part)"),
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="where to write, '-' for standard output (default: FILE without .part)"),
) -> None:
    """Rewrite an unfinished recording into a valid file; exit 0 if nothing was lost, 3 if some was."""
    from hapticop.cli.outputs import is_stdout, written
    from hapticop.recording.reading import RecordingError
    from hapticop.recording.recover import recover as rewrite

    try:
        with written(output, ".mcap") as target:
            found = rewrite(file, target)
    except RecordingError as error:
        raise _fail(str(error), 2) from None
    except FileExistsError as error:
        raise _fail(str(error), 2) from None
    except OSError as error:
        raise _fail(f"cannot recover {file}: {error.strerror}", 2) from None
    for line in found.describe():
        typer.echo(line, err=is_stdout(output))
    if not found.messages:
        raise typer.Exit(1)
    raise typer.Exit(0 if found.complete else 3)


def plot(
    file: Path = typer.Argument(..., help="a recording (RUN.mcap)"),
    streams: list[str] = typer.Argument(..., help="streams, or one element of one: handle_force robot_pose[2]"),
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="PNG to write, '-' for standard output (default: on screen, or "
                                            "FILE.png without a display)"),
    csv: Path | None = typer.Option(None, "--csv",
                                    help="write the samples as CSV instead of drawing them ('-': standard output)"),
) -> None:
    """Draw recorded streams against time, or export them as CSV."""
    from hapticop.cli.outputs import is_stdout, say_wrote, written
    from hapticop.recording import plot as plotting
    from hapticop.recording.reading import RecordingError

    try:
        chosen = plotting.select(file, streams)
    except RecordingError as error:
        raise _fail(str(error)) from None
    if csv is not None:
        if is_stdout(output):
            raise _fail("--csv and -o cannot both be standard output", 2)
        try:
            with written(csv, ".csv") as path:
                rows = plotting.write_csv(chosen, path)
        except OSError as error:
            why = "a FIFO nobody reads" if error.errno == errno.ENXIO else (error.strerror or str(error))
            raise _fail(f"{csv}: cannot write the CSV: {why}") from None
        typer.echo(say_wrote(csv, f" ({rows} samples)"), err=is_stdout(csv))
        if output is None:
            return
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise _fail("drawing needs matplotlib (pip install 'hapticop[report]'); --csv needs nothing") from None
    import os

    target = output if output is not None or os.environ.get("DISPLAY") else file.with_suffix(".png")
    title = f"{file.name}: {', '.join(streams)}"
    if target is None:
        plotting.draw(chosen, None, title)  # on screen
        return
    with written(target, ".png") as path:
        plotting.draw(chosen, path, title)
    typer.echo(say_wrote(target), err=is_stdout(target))


def replay(
    file: Path = typer.Argument(..., help="a recording (RUN.mcap)"),
    activities: list[str] = typer.Option([], "--activity", "-a",
                                         help="an activity to replay (again for more; default: the haptic "
                                              "controller, or every activity whose inputs were all recorded)"),
    tolerance: float = typer.Option(0.0, "--tolerance", min=0.0,
                                    help="the largest difference still a match, in the output's unit (default: "
                                         "equal to the bit, as a virtual-clock run replays)"),
    trust_blocks: bool = typer.Option(False, "--trust-blocks",
                                      help="import the modules this recording's composition names for its blocks "
                                           "(installed packages and PYTHONPATH only, never the recording's folder); "
                                           "without it only built-in blocks replay: a recording is data, not code"),
) -> None:
    """Feed the recorded inputs of activities back to their blocks, cycle by cycle under the virtual
    clock, and compare their outputs with the recorded ones; exit 1 on a mismatch, 2 if it cannot."""
    from hapticop.observe.replay import ReplayError
    from hapticop.observe.replay import replay as run_replay

    try:
        replayed = run_replay(file, activities, tolerance, trusted=trust_blocks)
    except ReplayError as error:
        raise _fail(str(error), 2) from None
    for one in replayed:
        _print_replayed(one)
    if not all(one.ok for one in replayed):
        diverged = any(one.diverged for one in replayed)
        typer.echo("the replayed life cycle left the recorded one" if diverged else
                   f"mismatch beyond the tolerance ({tolerance:g})", err=True)
        raise typer.Exit(1)


def _print_replayed(one) -> None:
    typer.echo(f"{one.activity} ({one.block}, thread {one.thread}): {one.cycles} cycles from {one.start_s:.3f} s "
               f"to {one.end_s:.3f} s; inputs {', '.join(one.inputs) or 'none'}")
    if one.diverged:
        typer.echo(f"  DIVERGED: {one.diverged}")
    for c in one.compared:
        verdict = "equal" if c.ok and c.max_diff == 0 else ("within tolerance" if c.ok else f"MISMATCH {c.first}")
        typer.echo(f"  {c.stream:<24} {c.samples:>8} samples  max |diff| {c.max_diff:<10.3g} {verdict}")
        if c.mismatches > 1 or c.missing or c.extra:
            typer.echo(f"  {'':<24} {c.mismatches} samples differ, {c.missing} not replayed, {c.extra} extra")


def report(
    file: Path = typer.Argument(..., help="a recording (RUN.mcap)"),
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="directory to write to (default: RUN.report beside the file); "
                                            "not '-': a report is several files"),
    from_streams: bool = typer.Option(False, "--from-streams",
                                      help="build the hallway's metrics and picture from the haptic, Falcon and "
                                           "odometry streams even when an activity (a simulated world) leaves them"),
    hallway: str | None = typer.Option(None, "--hallway",
                                       help="the hallway the run drove: a shipped scene, H1..H6; default the world's"),
    trust_blocks: bool = typer.Option(False, "--trust-blocks",
                                      help="import the modules this recording's composition names for its blocks "
                                           "(installed packages and PYTHONPATH only, never the recording's folder); "
                                           "without it only built-in blocks replay: a recording is data, not code"),
) -> None:
    """The results a run leaves (the hallway world's trajectory, metrics and picture), made again from
    its recording by replaying the activities that leave them; a run with none (the real robot) gets
    the hallway's metrics and picture from its recorded streams."""
    from rich.console import Console

    from hapticop.cli.outputs import is_stdout
    from hapticop.cli.report import print_results
    from hapticop.observe.replay import ReplayError, leaving_results, open_run, results

    if is_stdout(output):
        raise _fail("-o -: a report is a directory of files (metrics, picture), not one stream; name a directory", 2)
    target = output if output is not None else file.with_suffix(".report")
    try:
        run = open_run(file, trust_blocks)
        if from_streams or not leaving_results(run):
            _from_streams(run, target, hallway)
            return
        replayed, files = results(run, target)
    except ReplayError as error:
        raise _fail(str(error), 2) from None
    for one in replayed:
        _print_replayed(one)
    for path in files:
        typer.echo(f"wrote {path}")
    print_results(target, Console())
    if not all(one.ok for one in replayed):
        typer.echo("the replayed activities' outputs differ from the recorded ones: the results may too", err=True)
        raise typer.Exit(1)


def _from_streams(run, target: Path, hallway: str | None) -> None:
    """The hallway's metrics.json and run.png from the recorded streams (`sim.recorded_run`)."""
    from hapticop.sim.hallway_task import Hallway
    from hapticop.sim.metrics import compute_metrics, metrics_json
    from hapticop.sim.recorded_run import READ, MissingStream, hallway_log, writers
    from hapticop.sim.scene import Scene, to_mjcf

    composition = run.loaded.composition
    scene: str | Scene = hallway or "H1"
    if hallway is None:
        worlds = [a for a in run.loaded.activities.values() if a.spec.block == "scene_world"]
        named = getattr(worlds[0].params, "scene", None) if worlds else None
        scene = named if isinstance(named, (str, Scene)) else "H1"  # the world's scene: a shipped name or inline
        hallway = scene if isinstance(scene, str) else "the world's scene"
    try:
        geometry = Hallway.of(scene, to_mjcf(scene)) if isinstance(scene, Scene) else Hallway.named(scene)
    except ValueError as error:
        raise _fail(f"--hallway {hallway}: not a hallway (a scene with a hallway task, such as H1 to H6 of "
                    f"docs/hallway-experiment.md §2): {error}", 2) from None
    found = writers({name: spec.writer for name, spec in composition.streams.items() if name in run.streams},
                    {name: spec.block for name, spec in composition.activities.items()})
    try:
        log = hallway_log(found, run.series, geometry.start)
        metrics = compute_metrics(log, geometry)
    except (MissingStream, ValueError) as error:
        raise _fail(f"{run.path}: {error}", 2) from None
    target.mkdir(parents=True, exist_ok=True)
    (target / "metrics.json").write_text(metrics_json(metrics))
    used = [found[writer] for writer in READ if writer in found]
    typer.echo(f"{run.path}: hallway {hallway} from the streams {', '.join(used)} (the path is odometry)")
    typer.echo(f"wrote {target / 'metrics.json'}")
    try:
        from hapticop.sim.plot import plot_run

        typer.echo(f"wrote {plot_run(log, geometry, target / 'run.png', title=f'{hallway}, from {run.path.name}')}")
    except RuntimeError as error:  # matplotlib missing: the numbers are there
        typer.echo(f"no picture: {error}", err=True)
    for label, value, unit in (("ended by", metrics.ended_by, ""), ("stop error against dist2", metrics.e_stop_m, "m"),
                               ("least side clearance", metrics.side_clearance_min_m, "m"),
                               ("peak force", metrics.force_peak_n, "N"), ("rms force", metrics.force_rms_n, "N")):
        shown = value if isinstance(value, str) else f"{value:.3f} {unit}".strip()
        typer.echo(f"  {label:<26} {shown}")
