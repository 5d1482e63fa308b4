"""The judge users configure: generic metrics of any scene's run, and task targets declared in YAML.

Why: a scene of the user's own (a room, a box to push) needs a verdict without Python. The world
(`scene_world`) records the run; `run_metrics` turns the record into numbers every scene has
(collisions, least clearance to static geometry as MuJoCo measures it, path length and time, contact
and handle forces, oscillation), and each declared target (`reach`, `stop_before`, `keep_clearance`,
`push_body`, `no_collision`, `time_within`) reads them into one verdict row. docs/scenes.md lists them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

STILL_MPS = 0.02
"""Slower than this the robot is at rest (the hallway judge's still speed)."""
STILL_S = 1.0
"""At rest this long, with the operator done, the run has ended (docs/hallway-experiment.md §2)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Box(_Strict):
    min_m: tuple[float, float] = Field(description="its corner of least x and y (m)")
    max_m: tuple[float, float] = Field(description="its corner of largest x and y (m)")

    @model_validator(mode="after")
    def _ordered(self) -> Box:
        if self.min_m[0] > self.max_m[0] or self.min_m[1] > self.max_m[1]:
            raise ValueError("min_m must be below max_m in x and y")
        return self

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return (x >= self.min_m[0]) & (x <= self.max_m[0]) & (y >= self.min_m[1]) & (y <= self.max_m[1])


class Circle(_Strict):
    center_m: tuple[float, float] = Field(description="its centre x, y (m)")
    radius_m: float = Field(gt=0, description="its radius (m)")

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.hypot(x - self.center_m[0], y - self.center_m[1]) <= self.radius_m


class Region(_Strict):
    """A place on the floor: a box or a circle (give one)."""

    box: Box | None = Field(None, description="an axis-aligned box on the floor")
    circle: Circle | None = Field(None, description="a circle on the floor")

    @model_validator(mode="after")
    def _one(self) -> Region:
        if (self.box is None) == (self.circle is None):
            raise ValueError("a region is a box or a circle: give one")
        return self

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return (self.box or self.circle).contains(x, y)  # type: ignore[union-attr]


class Reach(_Strict):
    region: Region = Field(description="the robot's centre must be inside it at some moment of the run")


class StopBefore(_Strict):
    line: tuple[tuple[float, float], tuple[float, float]] = Field(
        description="two points (m) of the line; the robot starts on its 'before' side")
    margin_m: float = Field(0.0, ge=0, description="no corner of the footprint may come nearer the line than this")
    within_m: float | None = Field(None, gt=0, description="and the run must end with the footprint no farther "
                                   "than margin_m + this from the line (it stopped close to it)")

    @model_validator(mode="after")
    def _two_points(self) -> StopBefore:
        if self.line[0] == self.line[1]:
            raise ValueError("the line's two points are the same")
        return self


class KeepClearance(_Strict):
    min_m: float = Field(ge=0, description="the robot's least clearance to static geometry must stay at least this")


class PushBody(_Strict):
    body: str = Field(description="a movable body of the scene, by its name (or bodies[i])")
    to: Region = Field(description="where the body's centre must be at the end of the run")


class NoCollision(_Strict):
    pass


class TimeWithin(_Strict):
    max_s: float = Field(gt=0, description="the robot must have come to rest for good by then, counted from the "
                         "run's start (and be at rest at its end)")


class MetricBound(_Strict):
    """A bound on one of the run's metrics: any scene's (judge.json's `metrics`), or the hallway
    experiment's (metrics.json) when the scene has a `hallway` task."""

    name: str = Field(description="the metric, by its key")
    min: float | None = Field(None, description="it must be at least this")
    max: float | None = Field(None, description="it must be at most this")
    equals: bool | int | float | str | None = Field(None, description="it must be exactly this")
    relative_to: Literal["dist1_m", "dist2_m", "dist3_m"] | None = Field(
        None, description="min and max are offsets from this distance of the scene's hallway task")
    bounded_by: str | None = Field(None, description="a metric no smaller than this one: when this one is not "
                                   "measured, it stands in, shown as a bound, if it meets max")
    operators: tuple[str, ...] = Field((), description="only for runs of these operator variants (all if empty)")
    unless_operators: tuple[str, ...] = Field((), description="not for runs of these operator variants")

    @model_validator(mode="after")
    def _some_bound(self) -> MetricBound:
        if self.min is None and self.max is None and self.equals is None:
            raise ValueError("a metric target needs min, max or equals")
        if self.equals is not None and (self.min is not None or self.max is not None):
            raise ValueError("equals goes alone, without min or max")
        if self.bounded_by is not None and self.max is None:
            raise ValueError("bounded_by stands in for an upper bound: give max")
        return self

    def applies(self, operator: str) -> bool:
        """Whether it judges a run of this operator variant."""
        return (not self.operators or operator in self.operators) and operator not in self.unless_operators

    def limits(self, task: Mapping[str, float] | None = None) -> tuple[float | None, float | None]:
        """min and max, offset by the task distance they are relative to."""
        base = float((task or {})[self.relative_to]) if self.relative_to else 0.0
        return (None if self.min is None else base + self.min, None if self.max is None else base + self.max)

    def text(self, task: Mapping[str, float] | None = None) -> str:
        """What is asked, as the end-of-run table shows it."""
        if self.equals is not None:
            return "no" if self.equals is False else "yes" if self.equals is True else f"{self.equals:g}" \
                if isinstance(self.equals, (int, float)) else str(self.equals)
        if self.relative_to and self.relative_to not in (task or {}):
            return f"{self.relative_to} {self.min if self.min is not None else self.max:+g} (no hallway task)"
        low, high = self.limits(task)
        if low is not None and high is not None:
            return f"{low:+.2f} to {high:+.2f}"
        if low is not None:
            return f">= {low:.2f}" if self.relative_to else f">= {low:g}"
        return f"<= {high:g}"

    def verdict(self, metrics: Mapping[str, object], task: Mapping[str, float] | None = None
                ) -> tuple[object, bool | None, bool]:
        """(the value judged, the verdict (None: not measured), whether the value is `bounded_by`'s)."""
        value = metrics.get(self.name)
        if self.relative_to and self.relative_to not in (task or {}):  # no hallway task: nothing to offset from
            return value, None, False
        if self.equals is not None:
            if value is None or (isinstance(value, float) and value != value):
                return value, None, False
            return value, value == self.equals, False
        low, high = self.limits(task)
        stand_in = metrics.get(self.bounded_by) if self.bounded_by else None
        if not _measured(value) and _measured(stand_in) and high is not None and float(stand_in) <= high:  # type: ignore[arg-type]
            return stand_in, True, True
        if not _measured(value):
            return value, None, False
        number = float(value)  # type: ignore[arg-type]
        return value, (low is None or number >= low) and (high is None or number <= high), False


def _measured(value: object) -> bool:
    return value is not None and not (isinstance(value, float) and not math.isfinite(value))


class Target(_Strict):
    """One task target: exactly one of its keys."""

    reach: Reach | None = Field(None, description="the robot gets into a region")
    stop_before: StopBefore | None = Field(None, description="the robot's footprint stays short of a line")
    keep_clearance: KeepClearance | None = Field(None, description="the robot keeps away from static geometry")
    push_body: PushBody | None = Field(None, description="a movable body ends in a region")
    no_collision: NoCollision | None = Field(None, description="the robot never touches static geometry "
                                             "(`- no_collision` alone is enough)")
    time_within: TimeWithin | None = Field(None, description="the robot is at rest for good by a time")
    metric: MetricBound | None = Field(None, description="a metric of the run within bounds (the hallway's "
                                       "targets are such bounds: hapticop/sim/scenes/targets/hallway.yaml)")

    @model_validator(mode="before")
    @classmethod
    def _bare(cls, value: object) -> object:
        return {value: {}} if isinstance(value, str) else value  # `- no_collision` said without braces

    @model_validator(mode="after")
    def _one(self) -> Target:
        given = [k for k in type(self).model_fields if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"a target is one of {', '.join(type(self).model_fields)}: "
                             + ("none given" if not given else f"{', '.join(given)} given together"))
        return self

    @property
    def kind(self) -> str:
        return next(k for k in type(self).model_fields if getattr(self, k) is not None)


Targets = Annotated[tuple[Target, ...], Field(description="task targets the run is judged by "
                                                     "(docs/scenes.md, the judge)")]


@dataclass(frozen=True)
class Run:
    """What the world recorded: per sample the time (s), the robot's pose, its clearance to static geometry,
    the contact force on it, the force on the handle, the handle's velocity and the movable bodies' poses."""

    t: np.ndarray
    pose: np.ndarray  # (n, 3)
    clearance: np.ndarray
    contact_n: np.ndarray  # |contact force| on the robot
    handle_force: np.ndarray  # (n, 3)
    handle_velocity: np.ndarray  # (n, 3)
    bodies: np.ndarray  # (n, k, 3)
    body_names: tuple[tuple[str, ...], ...]  # each body's names: its scene name and bodies[i]
    footprint: tuple[float, float]  # length, width
    ended: str  # why the run ended ("" if the log simply stopped)


def run_metrics(run: Run) -> dict[str, object]:
    """The generic metrics of any scene's run."""
    from hapticop.sim.metrics import effort_and_oscillation, hold_weights

    t, w = run.t, hold_weights(run.t)
    moving = np.hypot(*np.diff(run.pose[:, :2], axis=0).T) > STILL_MPS * np.diff(t)
    settled = float(t[int(np.flatnonzero(moving)[-1]) + 1] - t[0]) if moving.any() else 0.0
    touching = run.clearance <= 0.0
    hand = np.sqrt((run.handle_force ** 2).sum(axis=1))
    channels = {"handle_velocity": run.handle_velocity} if run.handle_velocity.any() else {}
    osc = effort_and_oscillation(t, w, channels, math.inf, math.inf)
    return {
        "ended_by": run.ended or "log ended",
        "time_s": float(t[-1] - t[0]),
        "at_rest_after_s": settled if not moving[-1] else math.nan,
        "path_length_m": float(np.hypot(*np.diff(run.pose[:, :2], axis=0).T).sum()),
        "collisions": int(touching[0]) + int(np.count_nonzero(touching[1:] & ~touching[:-1])),
        "time_in_contact_with_static_s": float(w[touching].sum()),
        "least_clearance_m": float(run.clearance.min()),
        "contact_force_peak_n": float(run.contact_n.max()),
        "contact_force_mean_n": float((w * run.contact_n).sum() / w.sum()),
        "handle_force_peak_n": float(hand.max()),
        "handle_force_mean_n": float((w * hand).sum() / w.sum()),
        "oscillation_index_mps": osc["oscillation_index_mps"],
        "oscillation_s": osc["oscillation_s"],
    }


def _corners(pose: np.ndarray, footprint: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The footprint's four corners per sample: x (n, 4), y (n, 4)."""
    hl, hw = 0.5 * footprint[0], 0.5 * footprint[1]
    local = np.array([(hl, hw), (hl, -hw), (-hl, hw), (-hl, -hw)])
    c, s = np.cos(pose[:, 2:3]), np.sin(pose[:, 2:3])
    return (pose[:, 0:1] + c * local[:, 0] - s * local[:, 1], pose[:, 1:2] + s * local[:, 0] + c * local[:, 1])


def line_distance(run: Run, line: tuple[tuple[float, float], tuple[float, float]]) -> np.ndarray:
    """Per sample, the footprint's signed distance to the line: positive on the side the robot started."""
    (x1, y1), (x2, y2) = line
    nx, ny = y1 - y2, x2 - x1
    norm = math.hypot(nx, ny)
    cx, cy = _corners(run.pose, run.footprint)
    signed = ((cx - x1) * nx + (cy - y1) * ny) / norm
    start_side = 1.0 if ((run.pose[0, 0] - x1) * nx + (run.pose[0, 1] - y1) * ny) >= 0 else -1.0
    return (start_side * signed).min(axis=1)


def body_index(names: tuple[tuple[str, ...], ...], body: str) -> int | None:
    """A body named in a target: by its scene name or as bodies[i]."""
    return next((i for i, aliases in enumerate(names) if body in aliases), None)


def judge(run: Run, targets: tuple[Target, ...], metrics: Mapping[str, object] | None = None,
          operator: str = "") -> list[dict]:
    """One row per target (those for this operator variant): what was measured, what was asked, the verdict."""
    m = metrics or run_metrics(run)
    x, y = run.pose[:, 0], run.pose[:, 1]
    rows = []
    for target in targets:
        kind, spec = target.kind, getattr(target, target.kind)
        if isinstance(spec, MetricBound) and not spec.applies(operator):
            continue
        if isinstance(spec, Reach):
            inside = spec.region.contains(x, y)
            when = float(run.t[int(np.argmax(inside))] - run.t[0]) if inside.any() else None
            rows.append(_row(f"reach {_region_text(spec.region)}: reached at", when, "s", "reached",
                             when is not None))
        elif isinstance(spec, StopBefore):
            d = line_distance(run, spec.line)
            ok = bool(d.min() >= spec.margin_m)
            asked = f">= {spec.margin_m:g}"
            if spec.within_m is not None:
                ok = ok and bool(d[-1] <= spec.margin_m + spec.within_m)
                asked += f", ending <= {spec.margin_m + spec.within_m:g}"
            rows.append(_row(f"stop before the line: least distance (at the end {d[-1]:.3f} m)", float(d.min()),
                             "m", asked, ok))
        elif isinstance(spec, KeepClearance):
            least = float(m["least_clearance_m"])  # type: ignore[arg-type]
            rows.append(_row("keep clearance: least clearance", least, "m", f">= {spec.min_m:g}",
                             least >= spec.min_m))
        elif isinstance(spec, PushBody):
            i = body_index(run.body_names, spec.body)
            if i is None:
                raise ValueError(f"push_body: no movable body {spec.body!r} (the scene has "
                                 f"{', '.join(n[0] for n in run.body_names) or 'none'})")
            bx, by = run.bodies[-1, i, 0], run.bodies[-1, i, 1]
            ok = bool(spec.to.contains(np.array(bx), np.array(by)))
            rows.append(_row(f"push {spec.body} {_region_text(spec.to)}: it ended at", f"{bx:.3f}, {by:.3f}", "m",
                             "inside", ok))
        elif isinstance(spec, NoCollision):
            n = int(m["collisions"])  # type: ignore[call-overload]
            rows.append(_row("collisions with static geometry", n, "", "0", n == 0))
        elif isinstance(spec, TimeWithin):
            took = float(m["at_rest_after_s"])  # type: ignore[arg-type]
            rows.append(_row("at rest for good after", took if took == took else "still moving", "s",
                             f"<= {spec.max_s:g}", took <= spec.max_s))
        elif isinstance(spec, MetricBound):
            value, ok, bounded = spec.verdict(m)
            shown = value if _measured(value) else "not measured"
            rows.append({**_row(spec.name.replace("_", " ") + (f" (bound: {spec.bounded_by})" if bounded else ""),
                                shown, "", spec.text(), bool(ok)), "ok": ok})
        else:  # pragma: no cover - every kind is handled above
            raise AssertionError(kind)
    return rows


def _region_text(region: Region) -> str:
    if region.box is not None:
        return f"into the box {region.box.min_m}..{region.box.max_m}"
    assert region.circle is not None
    return f"into the circle at {region.circle.center_m} r {region.circle.radius_m:g}"


def _row(metric: str, value: object, unit: str, target: str, ok: bool) -> dict:
    shown = round(value, 3) if isinstance(value, float) else value
    return {"metric": metric, "value": shown, "unit": unit, "target": target, "ok": bool(ok)}


def metric_rows(metrics: Mapping[str, object]) -> list[dict]:
    """The generic metrics as rows of the end-of-run table (no verdicts: the targets give those)."""
    units = {"time_s": "s", "at_rest_after_s": "s", "path_length_m": "m", "time_in_contact_with_static_s": "s",
             "least_clearance_m": "m",
             "contact_force_peak_n": "N", "contact_force_mean_n": "N", "handle_force_peak_n": "N",
             "handle_force_mean_n": "N", "oscillation_index_mps": "m/s", "oscillation_s": "s"}
    rows = []
    for key, value in metrics.items():
        shown = None if isinstance(value, float) and not math.isfinite(value) else (
            round(value, 3) if isinstance(value, float) else value)
        rows.append({"metric": key.replace("_", " "), "value": shown, "unit": units.get(key, ""), "target": "",
                     "ok": None})
    return rows
