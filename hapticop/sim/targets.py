"""The targets a hallway run is judged by (docs/hallway-experiment.md §6), checked against its metrics.

A run passes when no check fails; a check whose metric was not measured is None, not a failure.
`success_rates` gives the sweep-level numbers that no single run can meet.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

from hapticop.sim.metrics import RunMetrics

if TYPE_CHECKING:
    from hapticop.sim.hallway_task import Hallway


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
    hold_speed_max_mps: float | None = 0.005  # stopped means still: no creep after the stop
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
                                  "t_norm_max", "hold_speed_max_mps", "force_peak_max_n", "saturation_max",
                                  "force_rate_rms_max_nps",
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
    upto("hold_speed", m.hold_speed_mps, targets.hold_speed_max_mps)
    upto("force_peak", m.force_peak_n, targets.force_peak_max_n)
    upto("saturation", m.saturation_frac, targets.saturation_max)
    upto("force_rate", m.force_rate_rms_nps, targets.force_rate_rms_max_nps)
    upto("hf_ratio", m.hf_ratio, targets.hf_ratio_max)
    upto("scan_step", scan_step(m, targets)[0], targets.scan_step_max_n)
    upto("dithering", m.dithering, targets.dithering_max)
    upto("e_pc_ratio", m.e_pc_ratio, targets.e_pc_ratio_max)
    atleast("risk_corr", m.risk_corr, targets.risk_corr_min)
    upto("risk_lag", m.risk_lag_s, targets.risk_lag_max_s)
    if targets.no_oscillation:
        checks["no_oscillation"] = not (m.sustained_oscillation or m.divergence)
    return TargetResult(all(v is not False for v in checks.values()), checks)


def scan_step(m: RunMetrics, targets: Targets) -> tuple[float, bool]:
    """The force step at a scan's arrival, and whether it is a bound. A run whose world does not see
    the arrivals shows the largest step in any cycle instead, if that already meets the target: the
    step in a cycle where a scan arrived can be no larger. A larger bound tells nothing (NaN)."""
    if m.scan_step_max_n == m.scan_step_max_n:
        return m.scan_step_max_n, False
    limit = targets.scan_step_max_n
    if limit is not None and m.cycle_step_max_n <= limit:
        return m.cycle_step_max_n, True
    return math.nan, False


def success_rates(runs: Sequence[RunMetrics]) -> dict[str, float]:
    """Sweep-level numbers of §6: crash rate and collision-free rate (target >= 0.98) over many runs."""
    n = len(runs)
    if n == 0:
        return {"crash_rate": math.nan, "collision_free_rate": math.nan}
    return {"crash_rate": sum(r.crash for r in runs) / n,
            "collision_free_rate": sum(r.n_collisions == 0 and not r.crash for r in runs) / n}


def judged_rows(m: RunMetrics, geometry: Hallway, variant: str, end_s: float | None = None) -> list[dict]:
    """Every metric of the run as a row of the end-of-run table: value, unit, target, verdict (None: no
    target, or not measured in this run). `hapticop compose --check` fails a run with a row whose verdict
    is False."""
    from hapticop.sim.metrics import OSCILLATION_LIMIT_MPS, SUSTAINED_S

    g, t = geometry, Targets.for_variant(variant)
    checks = targets_met(m, t).checks

    def row(name: str, value: object, unit: str = "", target: str = "", ok: bool | None = None) -> dict:
        if isinstance(value, bool):
            shown: object = "yes" if value else "no"
        elif isinstance(value, str) or value is None:
            shown = value
        else:
            shown = None if value != value or math.isinf(float(value)) else round(float(value), 3)  # type: ignore
        return {"metric": name, "value": shown, "unit": unit, "target": target if shown is not None or not target
                else f"{target} (not measured)", "ok": None if shown is None else ok}

    def bound(limit: float | None, fmt: str = "g", op: str = "<=") -> str:
        return "" if limit is None else f"{op} {limit:{fmt}}"

    lo, hi = t.e_stop_m or (math.nan, math.nan)
    step, step_bounded = scan_step(m, t)
    return [
        row("ended by", m.ended_by, "", "stopped", checks.get("completed")),
        row("crash", m.crash, "", "no", checks["no_crash"]),
        row(f"collisions (clearance under dist3 = {g.dist3_m} m)", m.n_collisions, "", "0", m.n_collisions == 0),
        row("time under dist3", m.time_below_dist3_s, "s"),
        row("least clearance", m.clearance_min_m, "m"),
        row(f"stop error against dist2 = {g.dist2_m} m (+ early)", m.e_stop_m, "m", f"{lo:+.2f} to {hi:+.2f}",
            checks.get("e_stop")),
        row("closest approach to the end wall", m.front_clearance_min_m, "m"),
        row(f"least side clearance (dist1 = {g.dist1_m} m)", m.side_clearance_min_m, "m",
            bound(None if t.side_below_dist1_m is None else g.dist1_m - t.side_below_dist1_m, ".2f", ">="),
            checks.get("side_clearance")),
        row("share of time under dist1", m.frac_below_dist1, "", bound(t.frac_below_dist1_max),
            checks.get("time_below_dist1")),
        row("rms under dist1", m.rms_dist1_violation_m, "m"),
        row("back at dist1 after", m.t_recover_dist1_s, "s", bound(t.recover_dist1_max_s),
            checks.get("recover_dist1")),
        row("run ended at (after the operator started)", m.completion_time_s if end_s is None else end_s, "s"),
        row("drift while stopped", m.hold_speed_mps, "m/s", bound(t.hold_speed_max_mps), checks.get("hold_speed")),
        row("autonomous reference time T_ref", m.t_ref_s, "s"),
        row("completion time / T_ref", m.t_norm, "", bound(t.t_norm_max), checks.get("t_norm")),
        row("peak force", m.force_peak_n, "N", bound(t.force_peak_max_n), checks.get("force_peak")),
        row("rms force", m.force_rms_n, "N"),
        row("share of time saturated", m.saturation_frac, "", bound(t.saturation_max), checks.get("saturation")),
        row("rms force rate", m.force_rate_rms_nps, "N/s", bound(t.force_rate_rms_max_nps), checks.get("force_rate")),
        row("force power above 10 Hz", m.hf_ratio, "", bound(t.hf_ratio_max), checks.get("hf_ratio")),
        row("largest force step at a scan" + (" (bound: largest in any cycle)" if step_bounded else ""), step, "N",
            bound(t.scan_step_max_n), checks.get("scan_step")),
        row("speed reversals near the stop", m.dithering, "", bound(t.dithering_max), checks.get("dithering")),
        row("least field energy", m.e_env_min_j, "J"),
        row("passivity controller's share", m.e_pc_ratio, "", bound(t.e_pc_ratio_max), checks.get("e_pc_ratio")),
        row("force against true risk, correlation", m.risk_corr, "", bound(t.risk_corr_min, op=">="),
            checks.get("risk_corr")),
        row("force behind true risk, lag", m.risk_lag_s, "s", bound(t.risk_lag_max_s), checks.get("risk_lag")),
        row("safety layer's authority, speed", m.authority_v, ""),
        row("safety layer's authority, turn", m.authority_w, ""),
        row("share of time the safety layer changes the command by over 10 %", m.frac_modified, ""),
        row("effort", m.effort_ns, "N s"),
        row("rms handle speed", m.handle_speed_rms_mps, "m/s"),
        row("oscillation index (largest 2 s rms, 1-10 Hz)", m.oscillation_index_mps, "m/s"),
        row(f"oscillation above {OSCILLATION_LIMIT_MPS} m/s (1 s rms), longest", m.oscillation_s, "s",
            f"<= {SUSTAINED_S:g}" if t.no_oscillation else "",
            not m.sustained_oscillation if t.no_oscillation else None),
        row("divergence (handle at its limit or force saturated > 0.5 s)", m.divergence, "", "no",
            not m.divergence if t.no_oscillation else None),
    ]
