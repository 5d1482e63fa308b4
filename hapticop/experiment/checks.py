"""An experiment file read and checked, every finding located in it: its fields (the model), each factor
path and value against the composition (a path the composition does not have and a value out of the
parameter's declared range are what the composition's own validation refuses once the value is put
there), and an empty grid."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from hapticop.composition.diagnostics import Diagnostic, Report
from hapticop.composition.model_errors import diagnostics_from
from hapticop.composition.yamlsource import Source, SourceError, plain, read_file
from hapticop.experiment.description import Experiment
from hapticop.experiment.grid import COMPOSITION, cells, runs, setting

STATE_LIMIT = 300
"""Markings explored per net for each value checked: the composition's own validation explores them fully."""
MAX_CHECKED_VALUES = 64
"""Values per factor validated against the composition; a range's ends and a sample between them beyond."""


@dataclass
class Loaded:
    path: Path
    source: Source
    experiment: Experiment | None
    report: Report

    @property
    def composition(self) -> Path:
        assert self.experiment is not None
        return (self.path.parent / self.experiment.composition).resolve()


def is_experiment(path: Path) -> bool:
    """An experiment file says `composition:` at its top where a composition says `threads:`."""
    try:
        tree = read_file(path).tree
    except SourceError:
        return False
    return isinstance(tree, dict) and "composition" in tree and "threads" not in tree


def load(path: str | Path, *, deep: bool = True) -> Loaded:
    """The file parsed and modelled; with `deep`, every factor value checked against the composition."""
    path = Path(path)
    report = Report(file=str(path))
    try:
        source = read_file(path)
    except SourceError as error:
        report.extend([error.diagnostic])
        return Loaded(path, Source(str(path), None), None, report)  # type: ignore[arg-type]
    try:
        experiment = Experiment.model_validate(plain(source.tree))
    except ValidationError as error:
        report.extend(source.place(d) for d in diagnostics_from(error, Experiment))
        return Loaded(path, source, None, report)
    loaded = Loaded(path, source, experiment, report)
    if not loaded.composition.exists():
        report.extend([source.place(Diagnostic("experiment-composition", f"no composition file {loaded.composition}",
                                               ("composition",)))])
        return loaded
    columns = [f.column for f in experiment.factors]
    if experiment.paths is not None and experiment.paths not in columns:
        report.extend([source.place(Diagnostic("experiment-paths", f"{experiment.paths!r} is not a factor's name",
                                               ("paths",), expected=", ".join(columns) or "a factor"))])
    if experiment.latin_hypercube is not None and not experiment.latin_hypercube.bounds:
        report.extend([source.place(Diagnostic("experiment-empty-grid", "the Latin hypercube has no bounds",
                                               ("latin_hypercube", "bounds")))])
    empty = [i for i, f in enumerate(experiment.factors) if not f.levels()]
    for i in empty:
        key = "values" if experiment.factors[i].values is not None else "range"
        report.extend([source.place(Diagnostic("experiment-empty-grid", "this factor takes no value: the grid is empty",
                                               ("factors", i, key)))])
    if not empty and not cells(experiment):
        report.extend([source.place(Diagnostic("experiment-empty-grid", "the grid has no cell", ("factors",)))])
    if deep and report.ok:
        report.extend(_check_values(loaded))
    return loaded


def _check_values(loaded: Loaded) -> list[Diagnostic]:
    """Each factor value (and the experiment's own patch) put into the composition alone and validated."""
    from hapticop.blocks.registry import search_beside
    from hapticop.composition.layers import resolve
    from hapticop.validation import validate_source
    from hapticop.validation.patches import apply_patch

    experiment, source = loaded.experiment, loaded.source
    search_beside(loaded.composition)  # its own blocks may sit beside it
    try:
        base = resolve(read_file(loaded.composition))
    except SourceError as error:
        return [error.diagnostic, source.place(Diagnostic("experiment-composition", "the composition cannot be read",
                                                          ("composition",)))]
    found: list[Diagnostic] = []

    def check(patch: dict | tuple, where: tuple, what: str, sets: tuple = ()) -> bool:
        tree = base.tree
        for one in (patch,) if isinstance(patch, dict) else patch:
            tree = apply_patch(tree, one)
        tree = setting(tree, sets)
        report = validate_source(Source(base.file, tree, base.text), STATE_LIMIT, scripted=False).report
        if report.ok:
            return True
        first = report.errors[0]
        found.append(source.place(Diagnostic(
            "experiment-value", f"{what}: {first.dotted_path}: {first.message}", where,
            expected=first.expected, hint=f"{experiment.composition} refuses it")))
        return False

    if experiment.patch and not check(experiment.patch, ("patch",), "the patch"):
        return found
    for i, factor in enumerate(experiment.factors):
        levels = factor.levels()
        if factor.path is None:
            continue
        if factor.path == COMPOSITION:
            for j, name in enumerate(levels):
                if not (loaded.path.parent / str(name)).exists():
                    found.append(source.place(Diagnostic("experiment-composition", f"no composition file {name}",
                                                         ("factors", i, "values", j))))
            continue
        picked = range(len(levels)) if len(levels) <= MAX_CHECKED_VALUES else _spread(len(levels))
        for j in picked:
            where: tuple[Any, ...] = (("factors", i, "values", j) if factor.values is not None
                                      else ("factors", i, "range"))
            if not check({}, where, f"{factor.path} = {levels[j]!r}", ((factor.path, levels[j]),)):
                break
    if experiment.latin_hypercube is not None:
        for path, bounds in experiment.latin_hypercube.bounds.items():
            for bound in bounds:
                if not check({}, ("latin_hypercube", "bounds", path), f"{path} = {bound!r}", ((path, bound),)):
                    break
    checked: set[int] = set()
    for run in runs(experiment):  # each cell patch once, with the first run it applies to and those it meets
        chosen = [i for i, c in enumerate(experiment.cell_patches)
                  if all(run.cell.labels.get(k) == v for k, v in c.where.items())]
        if chosen and not set(chosen) <= checked:
            checked.update(chosen)
            if not check(run.patches, ("cell_patches", chosen[-1], "patch"),
                         f"the cell patches {', '.join(map(str, chosen))} for {run.cell.labels}", run.sets):
                break
    for path in experiment.seeds.paths:
        last = experiment.seeds.start + experiment.seeds.count - 1
        check({}, ("seeds", "paths"), f"{path} = {last}", ((path, last),))
    return found


def _spread(n: int) -> list[int]:
    step = (n - 1) / (MAX_CHECKED_VALUES - 1)
    return sorted({round(i * step) for i in range(MAX_CHECKED_VALUES)})
