"""The cells (one combination of factor values) and runs (a cell and a seed) of an experiment, each with a
stable id: the id depends on what the run is, not on where it stands in the grid, so a resumed or
enlarged experiment skips exactly the runs it has."""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hapticop.experiment.description import Experiment


@dataclass(frozen=True)
class Cell:
    id: str
    values: dict[str, Any]  # path: value
    labels: dict[str, str]  # column: label


@dataclass(frozen=True)
class Run:
    id: str
    cell: Cell
    seed: int
    patches: tuple[dict, ...] = field(hash=False)  # merge patches on the composition, in order
    sets: tuple[tuple[str, Any], ...] = field(hash=False, default=())  # then each path set to its value


def setting(tree: Any, sets: Any) -> Any:
    """`tree` with each dotted path set to its value, replacing what was there (as `hapticop compose --set`
    would): two merge patches, the first clearing the paths, so a mapping value is not merged into the old."""
    from hapticop.composition.documents import dump
    from hapticop.composition.yamlsource import parse_text
    from hapticop.validation.patches import apply_patch

    cleared: dict = {}
    given: dict = {}
    for path, value in sets:
        _merge_into(cleared, path, None)
        _merge_into(given, path, value)
    if not given:
        return tree
    # read back from its own dump: every node the patches made has a line then, for the composition's checks
    return parse_text(dump(apply_patch(apply_patch(tree, cleared), given)), "<run>").tree


def _merge_into(patch: dict, path: str, value: Any) -> None:
    keys = path.split(".")
    for key in keys[:-1]:
        patch = patch.setdefault(key, {})
    patch[keys[-1]] = value


def latin_hypercube(n: int, seed: int, bounds: dict[str, tuple[float, float]]) -> list[dict[str, float]]:
    """`n` points, each dimension cut into `n` strata with one point in each, shuffled: numpy's seeded
    generator makes them the same on every machine."""
    rng = np.random.default_rng(seed)
    columns = {}
    for path, (low, high) in bounds.items():
        strata = (rng.permutation(n) + rng.random(n)) / n
        columns[path] = [float(low + s * (high - low)) for s in strata]
    return [{path: columns[path][i] for path in bounds} for i in range(n)]


def _digest(data: Any) -> str:
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:10]


def cells(experiment: Experiment) -> list[Cell]:
    crossed = [[(f, i) for i in range(len(f.levels()))] for f in experiment.factors]
    points = ([{}] if experiment.latin_hypercube is None else
              latin_hypercube(experiment.latin_hypercube.n, experiment.latin_hypercube.seed,
                              experiment.latin_hypercube.bounds))
    out = []
    for combination in itertools.product(*crossed):
        for point in points:
            values = {f.path or f"label:{f.column}": f.levels()[i] for f, i in combination} | point
            labels = {f.column: f.label(i) for f, i in combination}
            labels |= {path.rsplit(".", 1)[-1]: f"{v:.6g}" for path, v in point.items()}
            out.append(Cell(_digest(values), values, labels))
    return out


COMPOSITION = "composition"
"""The factor path that chooses the composition file rather than a value in it."""


def runs(experiment: Experiment) -> list[Run]:
    """Seed by seed, every cell before the next seed: a study stopped early has covered the cells evenly."""
    out = []
    grid = [(cell, experiment.seeds.count_for(cell.labels)) for cell in cells(experiment)]
    most = max((count for _, count in grid), default=0)
    for seed in range(experiment.seeds.start, experiment.seeds.start + most):
        for cell, count in grid:
            if seed >= experiment.seeds.start + count:
                continue
            sets = tuple((p, v) for p, v in cell.values.items() if p != COMPOSITION and not p.startswith("label:"))
            sets += tuple((path, seed) for path in experiment.seeds.paths)
            sets += tuple((path, seed + offset) for path, offset in experiment.seeds.offsets.items())
            sets += tuple((path, values[seed % len(values)]) for path, values in experiment.seeds.cycle.items())
            patches = (experiment.patch,) + tuple(extra.patch for extra in experiment.cell_patches
                                                  if all(cell.labels.get(k) == v for k, v in extra.where.items()))
            out.append(Run(f"{cell.id}-s{seed}", cell, seed, tuple(p for p in patches if p), sets))
    return out

