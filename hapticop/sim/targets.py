"""The targets a hallway run is judged by (docs/hallway-experiment.md §6), checked against its metrics.

A run passes when no check fails; a check whose metric was not measured is None, not a failure.
`success_rates` gives the sweep-level numbers that no single run can meet.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

from hapticop.sim.metrics import RunMetrics


@dataclass(frozen=True)
class Targets:
    """§6's targets for the recommended configuration; a None threshold is not checked."""

    completed: bool = True  # the run must end by stopping (not crash, not time-out)
    collision_free: bool = False  # per-run; §6 asks >= 98 % collision-free over the sweep (see success_rates)
    e_stop_m: tuple[float, float] | None = (-0.05, 0.10)
    side_below_dist1_m: float | None = 0.10  # c_side,min >= dist1 - this
    frac_below_dist1_max: float | None = 0.10
    recover_dist1_max_s: float | None = 3.0  # H2
    t_norm_max: float | None = 1.2
    force_peak_max_n: float | None = 8.0
    saturation_max: float | None = 0.0
    force_rate_rms_max_nps: float | None = 30.0
    hf_ratio_max: float | None = 0.05  # not for tremor runs
    scan_step_max_n: float | None = 0.1
    dithering_max: int | None = 0
    e_pc_ratio_max: float | None = 0.20  # zero delay
    risk_corr_min: float | None = 0.8
    risk_lag_max_s: float | None = 0.10  # with prediction; 0.15 s + RTT without
    no_oscillation: bool = True

    @classmethod
    def for_variant(cls, name: str) -> Targets:
        """Cautious operators may stop up to 0.25 m early; tremor runs are not held to the HF ratio."""
        if name.startswith("cautious"):
            return cls(e_stop_m=(-0.05, 0.25))
        if name.startswith("tremor"):
            return cls(hf_ratio_max=None)
        return cls()

    @classmethod
    def delay_pass(cls) -> Targets:
        """§7.7's pass criterion for the delay sweep: no crash, no sustained oscillation, |e_stop| <= 0.10 m."""
        none = {f: None for f in ("side_below_dist1_m", "frac_below_dist1_max", "recover_dist1_max_s",
                                  "t_norm_max", "force_peak_max_n", "saturation_max", "force_rate_rms_max_nps",
                                  "hf_ratio_max", "scan_step_max_n", "dithering_max", "e_pc_ratio_max",
                                  "risk_corr_min", "risk_lag_max_s")}
        return replace(cls(), completed=False, e_stop_m=(-0.10, 0.10), **none)


class TargetResult(NamedTuple):
    ok: bool  # no check failed
    checks: dict[str, bool | None]  # None: not measured in this run


def targets_met(m: RunMetrics, targets: Targets) -> TargetResult:
    """Check one run against §6. Checks whose metric was not measured (NaN) are None and do not fail."""
    checks: dict[str, bool | None] = {"no_crash": not m.crash}

    def upto(name: str, value: float | int | None, limit: float | None) -> None:
        if limit is not None:
            checks[name] = None if value is None or value != value else bool(value <= limit)

    def atleast(name: str, value: float, limit: float | None) -> None:
        if limit is not None:
            checks[name] = None if value != value else bool(value >= limit)

    if targets.completed:
        checks["completed"] = m.ended_by == "stopped"
    if targets.collision_free:
        checks["collision_free"] = m.n_collisions == 0
    if targets.e_stop_m is not None:
        lo, hi = targets.e_stop_m
        checks["e_stop"] = None if m.e_stop_m != m.e_stop_m else bool(lo <= m.e_stop_m <= hi)
    upto("side_clearance", m.side_deficit_m, targets.side_below_dist1_m)
    upto("time_below_dist1", m.frac_below_dist1, targets.frac_below_dist1_max)
    upto("recover_dist1", m.t_recover_dist1_s, targets.recover_dist1_max_s)
    upto("t_norm", m.t_norm, targets.t_norm_max)
    upto("force_peak", m.force_peak_n, targets.force_peak_max_n)
    upto("saturation", m.saturation_frac, targets.saturation_max)
    upto("force_rate", m.force_rate_rms_nps, targets.force_rate_rms_max_nps)
    upto("hf_ratio", m.hf_ratio, targets.hf_ratio_max)
    upto("scan_step", m.scan_step_max_n, targets.scan_step_max_n)
    upto("dithering", m.dithering, targets.dithering_max)
    upto("e_pc_ratio", m.e_pc_ratio, targets.e_pc_ratio_max)
    atleast("risk_corr", m.risk_corr, targets.risk_corr_min)
    upto("risk_lag", m.risk_lag_s, targets.risk_lag_max_s)
    if targets.no_oscillation:
        checks["no_oscillation"] = not (m.sustained_oscillation or m.divergence)
    return TargetResult(all(v is not False for v in checks.values()), checks)


def success_rates(runs: Sequence[RunMetrics]) -> dict[str, float]:
    """Sweep-level numbers of §6: crash rate and collision-free rate (target >= 0.98) over many runs."""
    n = len(runs)
    if n == 0:
        return {"crash_rate": math.nan, "collision_free_rate": math.nan}
    return {"crash_rate": sum(r.crash for r in runs) / n,
            "collision_free_rate": sum(r.n_collisions == 0 and not r.crash for r in runs) / n}
