"""The hallway run's end-of-run table: every metric of §5 (docs/hallway-experiment.md) as a row, with the
verdicts of the targets the scene declares (§6's are hapticop/sim/scenes/targets/hallway.yaml, bounds of
the judge users configure: hapticop.sim.judge.MetricBound).

Why: a hallway run and any other scene are judged by one mechanism, the declared targets; this module only
says how the hallway's metrics read in the table. A target whose metric was not measured has no verdict
(None), not a failure. `success_rates` gives the sweep-level numbers that no single run can meet.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict
from typing import TYPE_CHECKING

from hapticop.sim.judge import MetricBound, Target
from hapticop.sim.metrics import OSCILLATION_LIMIT_MPS, RunMetrics

if TYPE_CHECKING:
    from hapticop.sim.hallway_task import Hallway


def rows_table(g: Hallway) -> tuple[tuple[str, str, str], ...]:
    """(metric key, label, unit) of each row, in the table's order; the labels name the task's distances."""
    return (
        ("ended_by", "ended by", ""),
        ("crash", "crash", ""),
        ("n_collisions", f"collisions (clearance under dist3 = {g.dist3_m} m)", ""),
        ("time_below_dist3_s", "time under dist3", "s"),
        ("clearance_min_m", "least clearance", "m"),
        ("e_stop_m", f"stop error against dist2 = {g.dist2_m} m (+ early)", "m"),
        ("front_clearance_min_m", "closest approach to the end wall", "m"),
        ("side_clearance_min_m", f"least side clearance (dist1 = {g.dist1_m} m)", "m"),
        ("frac_below_dist1", "share of time under dist1", ""),
        ("rms_dist1_violation_m", "rms under dist1", "m"),
        ("t_recover_dist1_s", "back at dist1 after", "s"),
        ("end_s", "run ended at (after the operator started)", "s"),
        ("hold_speed_mps", "drift while stopped", "m/s"),
        ("t_ref_s", "autonomous reference time T_ref", "s"),
        ("t_norm", "completion time / T_ref", ""),
        ("force_peak_n", "peak force", "N"),
        ("force_rms_n", "rms force", "N"),
        ("saturation_frac", "share of time saturated", ""),
        ("force_rate_rms_nps", "rms force rate", "N/s"),
        ("hf_ratio", "force power above 10 Hz", ""),
        ("scan_step_max_n", "largest force step at a scan", "N"),
        ("dithering", "speed reversals near the stop", ""),
        ("e_env_min_j", "least field energy", "J"),
        ("e_pc_ratio", "passivity controller's share", ""),
        ("risk_corr", "force against true risk, correlation", ""),
        ("risk_lag_s", "force behind true risk, lag", "s"),
        ("authority_v", "safety layer's authority, speed", ""),
        ("authority_w", "safety layer's authority, turn", ""),
        ("frac_modified", "share of time the safety layer changes the command by over 10 %", ""),
        ("effort_ns", "effort", "N s"),
        ("handle_speed_rms_mps", "rms handle speed", "m/s"),
        ("oscillation_index_mps", "oscillation index (largest 2 s rms, 1-10 Hz)", "m/s"),
        ("oscillation_s", f"oscillation above {OSCILLATION_LIMIT_MPS} m/s (1 s rms), longest", "s"),
        ("divergence", "divergence (handle at its limit or force saturated > 0.5 s)", ""),
    )


BOUND_LABELS = {"cycle_step_max_n": "largest in any cycle"}
"""How a stand-in metric (`bounded_by`) reads after its row's label."""


def bounds_for(targets: Iterable[Target], variant: str) -> list[MetricBound]:
    """The metric bounds among `targets` that judge a run of this operator variant."""
    return [t.metric for t in targets if t.metric is not None and t.metric.applies(variant)]


def hallway_metric(name: str) -> bool:
    """Whether a metric is the hallway's (metrics.json), so its bound goes in the hallway's table."""
    return name in RunMetrics.__dataclass_fields__


def checks(m: RunMetrics, g: Hallway, targets: Iterable[Target], variant: str) -> dict[str, bool | None]:
    """Each hallway metric bound's verdict by its metric's key (None: not measured); a metric with two
    bounds (two operators') has the one for this variant."""
    values, task = asdict(m), _task(g)
    return {b.name: b.verdict(values, task)[1] for b in bounds_for(targets, variant) if hallway_metric(b.name)}


def judged_rows(m: RunMetrics, g: Hallway, variant: str, targets: Sequence[Target],
                end_s: float | None = None) -> list[dict]:
    """Every metric of the run as a row of the end-of-run table: value, unit, target, verdict (None: no
    target, or not measured in this run). `hapticop compose --check` fails a run with a row whose verdict
    is False."""
    values, task = asdict(m), _task(g)
    values["end_s"] = m.completion_time_s if end_s is None else end_s
    bounds = {b.name: b for b in bounds_for(targets, variant) if hallway_metric(b.name)}
    rows = []
    for key, label, unit in rows_table(g):
        bound = bounds.get(key)
        value, ok, bounded = bound.verdict(values, task) if bound else (values[key], None, False)
        if bounded:
            label += f" (bound: {BOUND_LABELS.get(bound.bounded_by or '', bound.bounded_by)})"  # type: ignore[union-attr]
        rows.append(_row(label, value, unit, bound.text(task) if bound else "", ok))
    return rows


def _task(g: Hallway) -> dict[str, float]:
    return {"dist1_m": g.dist1_m, "dist2_m": g.dist2_m, "dist3_m": g.dist3_m}


def _row(name: str, value: object, unit: str, target: str, ok: bool | None) -> dict:
    if isinstance(value, bool):
        shown: object = "yes" if value else "no"
    elif isinstance(value, str) or value is None:
        shown = value
    else:
        shown = None if value != value or math.isinf(float(value)) else round(float(value), 3)  # type: ignore
    return {"metric": name, "value": shown, "unit": unit, "target": target if shown is not None or not target
            else f"{target} (not measured)", "ok": None if shown is None else ok}


def success_rates(runs: Sequence[RunMetrics]) -> dict[str, float]:
    """Sweep-level numbers of §6: crash rate and collision-free rate (target >= 0.98) over many runs."""
    n = len(runs)
    if n == 0:
        return {"crash_rate": math.nan, "collision_free_rate": math.nan}
    return {"crash_rate": sum(r.crash for r in runs) / n,
            "collision_free_rate": sum(r.n_collisions == 0 and not r.crash for r in runs) / n}
