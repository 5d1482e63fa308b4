"""The experiment file as pydantic models: what is varied, how often, what is kept and what it is judged by."""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Span(Strict):
    """`start`, `start + step`, ... up to and including `stop` (within a millionth of a step)."""

    start: float
    stop: float
    step: float = Field(gt=0)


class Factor(Strict):
    """One parameter path of the composition and the values it takes; a mapping value is merged at the path."""

    path: str | None = Field(None, description="dotted path in the composition, e.g. "
                             "activities.haptic.params.force_model.kind; "
                      "`composition`: the composition file itself (relative to the experiment file); null: a "
                      "label only, which `cell_patches` give meaning to")
    name: str = Field("", description="its column in the table (default: the path's last key)")
    values: list[Any] | None = None
    range: Span | None = None
    labels: list[str] | None = Field(None, description="a name per value, for tables (default: the value)")

    @model_validator(mode="after")
    def _one_source(self) -> Factor:
        if (self.values is None) == (self.range is None):
            raise ValueError("a factor has either `values` or `range`")
        if self.path is None and not self.name:
            raise ValueError("a factor without a path needs a `name`")
        if self.labels is not None and len(self.labels) != len(self.levels()):
            raise ValueError("`labels` needs one name per value")
        return self

    @property
    def column(self) -> str:
        return self.name or (self.path or "").rsplit(".", 1)[-1]

    def levels(self) -> list[Any]:
        if self.values is not None:
            return list(self.values)
        span = self.range
        count = math.floor((span.stop - span.start) / span.step + 1e-6) + 1
        return [round(span.start + i * span.step, 12) for i in range(max(count, 0))]

    def label(self, index: int) -> str:
        value = self.levels()[index]
        return self.labels[index] if self.labels else (value if isinstance(value, str) else json.dumps(value))


class LatinHypercube(Strict):
    """`n` points over the named paths' intervals, one stratum each per dimension, from `seed`: the same every time."""

    n: int = Field(ge=1)
    seed: int = 0
    bounds: dict[str, tuple[float, float]] = Field(description="path: [low, high]")


class SeedsWhere(Strict):
    """Another number of seeds for the cells whose factor labels match `where` (column: label)."""

    where: dict[str, str]
    count: int = Field(ge=1)


class CellPatch(Strict):
    """A merge patch for the cells whose factor labels match `where`, after the experiment's own `patch` and
    the cell patches before it (in order: a key cleared by one may be given anew by the next)."""

    where: dict[str, str]
    patch: dict[str, Any]


class Seeds(Strict):
    """Repetitions of each cell: seed `start`, `start + 1`, ... handed to the run and written at `paths`."""

    count: int = Field(1, ge=1)
    start: int = 0
    paths: list[str] = Field(default_factory=list, description="composition paths that take the seed too")
    offsets: dict[str, int] = Field(default_factory=dict, description="paths that take the seed plus this")
    cycle: dict[str, list[Any]] = Field(default_factory=dict, description="paths that take values[seed % len]")
    cells: list[SeedsWhere] = Field(default_factory=list, description="the first that matches a cell sets its count")

    def count_for(self, labels: dict[str, str]) -> int:
        for rule in self.cells:
            if all(labels.get(k) == v for k, v in rule.where.items()):
                return rule.count
        return self.count


Comparison = Literal["<", "<=", ">", ">=", "==", "!="]


class Target(Strict):
    """A metric judged per cell: every run (`all`), their `mean`, or the `fraction` of runs that pass at least
    `fraction`."""

    metric: str
    comparison: Comparison
    value: float | bool
    statistic: Literal["all", "mean", "fraction"] = "all"
    fraction: float = Field(1.0, ge=0, le=1)
    name: str = ""

    @property
    def title(self) -> str:
        judged = {"all": "every run", "mean": "mean", "fraction": f"{100 * self.fraction:g} % of runs"}[self.statistic]
        return self.name or f"{self.metric} {self.comparison} {self.value:g} ({judged})"


class Experiment(Strict):
    version: Literal[1] = 1
    name: str
    doc: str = ""
    composition: str = Field(description="the composition file, relative to this file")
    patch: dict[str, Any] = Field(default_factory=dict, description="a merge patch on the composition for every run")
    factors: list[Factor] = Field(default_factory=list)
    cell_patches: list[CellPatch] = Field(default_factory=list)
    latin_hypercube: LatinHypercube | None = None
    seeds: Seeds = Field(default_factory=Seeds)
    clock: Literal["virtual", "realtime"] = "virtual"
    duration_s: float | None = Field(None, gt=0, description="stop each run after this long (default: its own end)")
    time_limit_s: float = Field(600.0, gt=0, description="a run still going after this long (wall) is killed, failed")
    metrics: list[str] | None = Field(None, description="the metrics to keep (default: every one a run reports)")
    targets: list[Target] = Field(default_factory=list)
    summaries: list[Literal["hallway_sweep", "hallway_readme", "delay", "delay_goal"]] = Field(
        default_factory=list, description="named tables the report adds (hapticop.experiment.summaries)")
    paths: str | None = Field(None, description="a factor's name: keep each run's robot path (from its world's "
                              "trajectory, every 0.1 s) and draw a picture of them per value of that factor "
                              "(the scene's, say)")
    cpus_per_run: float = Field(1.0, gt=0, description="what a run declares to a Ray cluster")
    retries: int = Field(2, ge=0, description="a run lost with its node is tried again this often (Ray)")

    def meaning(self, composition_text: str) -> str:
        """A digest of what decides the runs (not the targets, the docs or the name): a table is resumed only
        by the experiment that wrote it."""
        decisive = self.model_dump(exclude={"doc", "targets", "name", "retries", "cpus_per_run", "time_limit_s",
                                                 "summaries", "paths"})
        decisive["composition"] = hashlib.sha256(composition_text.encode()).hexdigest()
        return hashlib.sha256(json.dumps(decisive, sort_keys=True, default=str).encode()).hexdigest()[:16]
