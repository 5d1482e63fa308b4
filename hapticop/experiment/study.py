"""An experiment run: its runs not yet in the table, on the local pool or a Ray cluster, every row written
as it comes back."""

from __future__ import annotations

from pathlib import Path

from hapticop import __version__
from hapticop.experiment.checks import Loaded
from hapticop.experiment.grid import COMPOSITION, Run, runs
from hapticop.experiment.progress import Progress
from hapticop.experiment.runner import job
from hapticop.experiment.table import append, finished, open_table, row


def default_out(loaded: Loaded) -> Path:
    return loaded.path.parent / "results" / loaded.path.stem


def composition_of(loaded: Loaded, run: Run) -> Path:
    """The run's composition file: the experiment's, or the one its `composition` factor names."""
    chosen = run.cell.values.get(COMPOSITION)
    return (loaded.path.parent / chosen).resolve() if chosen else loaded.composition


def composition_text(loaded: Loaded) -> str:
    """What the compositions mean after `extends:`: their resolved trees, so a comment edit changes nothing."""
    import json

    from hapticop.composition.layers import resolve
    from hapticop.composition.yamlsource import plain, read_file

    files = [loaded.composition] + [(loaded.path.parent / v).resolve() for f in loaded.experiment.factors
                                    if f.path == COMPOSITION for v in f.levels()]
    return json.dumps([plain(resolve(read_file(f)).tree) for f in files], sort_keys=True, default=str)


def run_study(loaded: Loaded, out: Path, *, workers: int = 2, ray: str | None = None,
              progress: Progress | None = None, retry_failed: bool = False) -> tuple[int, int]:
    """(runs done now, of which failed). A run the table holds is not run again, unless it failed and
    `retry_failed` says so. Raises `table.TableMismatch` for another experiment's table."""
    experiment = loaded.experiment
    assert experiment is not None
    open_table(out, experiment.name, experiment.meaning(composition_text(loaded)), __version__)
    every = runs(experiment)
    have = finished(out, retry_failed)
    todo = [r for r in every if r.id not in have]
    by_id = {r.id: r for r in todo}
    jobs = [(r.id, job(composition_of(loaded, r), r.patches, r.sets, r.seed, experiment.clock,
                       experiment.duration_s, experiment.metrics, experiment.paths is not None)) for r in todo]
    progress = progress or Progress(len(every), len(every) - len(todo))
    if ray:
        from hapticop.experiment.cluster import run_ray

        results = run_ray(jobs, ray, experiment.time_limit_s, experiment.cpus_per_run, experiment.retries)
    else:
        from hapticop.experiment.local import run_local

        results = run_local(jobs, workers, experiment.time_limit_s)
    done = failed = 0
    try:
        for run_id, outcome in results:
            run = by_id[run_id]
            append(out, [row(run.id, run.cell.id, run.cell.labels, run.seed, __version__, outcome)])
            done += 1
            failed += outcome["status"] != "done"
            progress.update(outcome["status"] != "done")
    finally:
        progress.close()
    return done, failed
