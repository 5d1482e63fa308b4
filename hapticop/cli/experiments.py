"""`hapticop experiment run|report`: declared studies (hapticop.experiment, docs/experiments.md)."""

from __future__ import annotations

import signal
from pathlib import Path

import typer

experiment = typer.Typer(help="Declared experiments: run them (locally or on Ray) and report them.",
                         no_args_is_help=True, add_completion=False)


def _load(file: Path, deep: bool):
    from hapticop.experiment.checks import load

    loaded = load(file, deep=deep)
    if not loaded.report.ok:
        for diagnostic in loaded.report.sorted():
            typer.echo(diagnostic.to_text(), err=True)
        raise typer.Exit(1)
    return loaded


@experiment.command("run")
def run(
    file: Path = typer.Argument(..., help="the experiment file"),
    ray: str | None = typer.Option(None, "--ray", help="a Ray cluster's address, or 'auto'; 'local' starts one here"),
    workers: int = typer.Option(2, min=1, help="runs at a time on the local pool"),
    out: Path | None = typer.Option(None, help="the results folder (default: results/NAME beside the file)"),
    retry_failed: bool = typer.Option(False, "--retry-failed", help="run again the runs recorded as failed (by "
                                      "default they are kept as they are: a failure is a result)"),
) -> None:
    """Run every run not yet in the results folder; an interrupted study resumes where it stopped."""
    from hapticop.experiment.study import default_out, run_study
    from hapticop.experiment.table import TableMismatch

    loaded = _load(file, deep=True)
    folder = out or default_out(loaded)
    previous = signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops it as Ctrl+C does
    try:
        done, failed = run_study(loaded, folder, workers=workers, ray=ray, retry_failed=retry_failed)
    except (TableMismatch, RuntimeError) as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(1) from None
    except KeyboardInterrupt:
        typer.echo(f"\ninterrupted: the runs that finished are kept in {folder}, those in flight were stopped; "
                   "the same command resumes", err=True)
        raise typer.Exit(130) from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    typer.echo(f"{folder}: {done} runs now, {failed} failed")


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


@experiment.command("report")
def report(
    file: Path = typer.Argument(..., help="the experiment file"),
    out: Path | None = typer.Option(None, help="the results folder (default: results/NAME beside the file)"),
    docs: bool = typer.Option(False, "--docs", help="also rewrite the tables of this experiment in README.md and "
                              "docs/*.md (between their `<!-- experiment NAME SUMMARY -->` markers) and "
                              "redraw its summaries' pictures in docs/figures/"),
) -> None:
    """Judge each cell against the targets and draw the metrics: FOLDER/report/report.md and its PNGs."""
    from hapticop.experiment.report import write_report
    from hapticop.experiment.study import default_out
    from hapticop.experiment.table import read

    loaded = _load(file, deep=False)
    folder = out or default_out(loaded)
    if not (folder / "manifest.json").exists():
        typer.echo(f"error: {folder}: no results (run `hapticop experiment run {file}` first)", err=True)
        raise typer.Exit(1)
    table = read(folder)
    page = write_report(loaded.experiment, table, folder / "report")
    typer.echo(f"report: {page}")
    if docs:
        from hapticop.experiment.regions import update
        from hapticop.experiment.report import summary, summary_figures

        root = Path(__file__).resolve().parents[2]
        for doc in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
            text = doc.read_text()
            new = update(text, loaded.experiment.name, lambda name: summary(name, table))
            if new != text:
                doc.write_text(new)
                typer.echo(f"updated {doc.relative_to(root)}")
        for picture in summary_figures(loaded.experiment, table, root / "docs" / "figures"):
            typer.echo(f"drew {picture.relative_to(root)}")
