"""`hapticop info`, `recover` and `plot`: looking at a run's MCAP recording."""

from __future__ import annotations

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
    output: Path | None = typer.Option(None, "-o", "--output", help="where to write (default: FILE without .part)"),
) -> None:
    """Rewrite an unfinished recording into a valid file; exit 0 if nothing was lost, 3 if some was."""
    from hapticop.recording.recover import recover as rewrite

    try:
        found = rewrite(file, output)
    except FileExistsError as error:
        raise _fail(str(error), 2) from None
    except OSError as error:
        raise _fail(f"cannot recover {file}: {error.strerror}", 2) from None
    for line in found.describe():
        typer.echo(line)
    if not found.messages:
        raise typer.Exit(1)
    raise typer.Exit(0 if found.complete else 3)


def plot(
    file: Path = typer.Argument(..., help="a recording (RUN.mcap)"),
    streams: list[str] = typer.Argument(..., help="streams, or one element of one: handle_force robot_pose[2]"),
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="PNG to write (default: on screen, or FILE.png without a display)"),
    csv: Path | None = typer.Option(None, "--csv", help="write the samples as CSV instead of drawing them"),
) -> None:
    """Draw recorded streams against time, or export them as CSV."""
    from hapticop.recording import plot as plotting
    from hapticop.recording.reading import RecordingError

    try:
        chosen = plotting.select(file, streams)
    except RecordingError as error:
        raise _fail(str(error)) from None
    if csv is not None:
        rows = plotting.write_csv(chosen, csv)
        typer.echo(f"wrote {csv} ({rows} samples)")
        if output is None:
            return
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise _fail("drawing needs matplotlib (pip install 'hapticop[report]'); --csv needs nothing") from None
    import os

    target = output if output is not None or os.environ.get("DISPLAY") else file.with_suffix(".png")
    written = plotting.draw(chosen, target, f"{file.name}: {', '.join(streams)}")
    if written is not None:
        typer.echo(f"wrote {written}")
