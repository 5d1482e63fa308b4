"""The hallway experiment's metrics (docs/hallway-experiment.md §5), computed from a run's log.

Why: every condition of §4 is compared on the same deterministic numbers. `compute_metrics`
turns a `TrajectoryRecorder` (or a loaded .npz) into `RunMetrics`; `targets.py` judges them.

Metrics that need a channel the run did not record come out NaN (or None) and their target is "not measured".
Time-weighted quantities weight each sample by the interval to the next one (sample and hold).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from hapticop.sim.recording import TrajectoryRecorder, as_channels

F64 = NDArray[np.float64]

EndReason = Literal["stopped", "crash", "timeout", "incomplete"]

OSCILLATION_LIMIT_MPS = 0.02
"""§5: handle velocity in the 1-10 Hz band with an rms above this is oscillating, if it lasts."""
OSCILLATION_WINDOW_S = 2.0
"""§5: the oscillation index is the rms of the band over sliding windows this long."""
PERSISTENCE_WINDOW_S = 1.0
"""§5: whether the band stays above the limit is judged over windows this long: one period of the band's
lowest frequency, so a steady oscillation anywhere in the band keeps every window's rms steady, while a
transient lifts only the windows that hold it (a 2 s window would join two transients 2 s apart)."""
SUSTAINED_S = 2.0
"""§5: an oscillation is sustained when the band's 1 s rms stays above the limit for more than this."""


@dataclass(frozen=True)
class RunMetrics:
    """§5's metrics for one run, over [start, end of run]. Distances in m, times in s, forces in N."""

    ended_by: EndReason  # §2: still 1 s in the far half, crash, t_max, or the log ended first
    t_end_s: float
    # 1. collisions
    crash: bool  # footprint clearance reached 0
    n_collisions: int  # rising edges of clearance < dist3, leaving only above dist3 + hysteresis
    time_below_dist3_s: float
    clearance_min_m: float
    # 2. stop
    e_stop_m: float  # front clearance at the end minus dist2; + = stopped early; NaN after a crash
    front_clearance_min_m: float  # closest approach to the end wall (overshoot if below dist2)
    # 3. side keeping
    side_clearance_min_m: float
    side_deficit_m: float  # dist1 - c_side,min: how far the robot came inside the comfort distance
    frac_below_dist1: float
    rms_dist1_violation_m: float  # rms of (dist1 - c_side)+
    t_recover_dist1_s: float  # from first dropping below dist1 to first being back at it; 0 if never below
    # 4. completion time
    completion_time_s: float  # start to the moment the final still period began; NaN unless stopped
    hold_speed_mps: float  # how far the robot moved over the last half of the final still period, per second
    t_ref_s: float  # travel / v_cruise + v_cruise / (2 a_b) + tau_r
    t_norm: float
    # 5. peak force and saturation
    force_peak_n: float  # max |F_env|
    force_rms_n: float  # rms |F_env|
    saturation_frac: float  # time with any axis of the device force (or F_env) at the limit
    # 6. smoothness
    force_rate_rms_nps: float  # rms |dF_env/dt|
    hf_ratio: float  # power of F_env above 10 Hz / total power (mean included)
    scan_step_max_n: float  # largest |F_env| step in a cycle where a scan arrived (NaN: arrivals not seen)
    cycle_step_max_n: float  # largest |F_env| step in any cycle: a bound on the step at a scan
    dithering: int | None  # sign reversals of the commanded v within near_stop_m of the stop line
    # 7. energy and passivity
    e_env_min_j: float  # min over time of E_env = -int F_env . dp/dt dt (0 at the start)
    e_pc_j: float
    e_pc_ratio: float  # E_PC / int |F_env . dp/dt| dt
    pc_active_frac: float
    # 8. transparency
    risk_corr: float  # corr(|F_env|, rho*)
    risk_lag_s: float  # lag of |F_env| behind rho* at the cross-correlation peak
    # 9. authority
    authority_v: float  # int |v_exec - v_cmd| dt / int |v_cmd| dt
    authority_w: float
    frac_modified: float  # time the safety layer changes v or omega by more than 10 %
    # 10. effort
    effort_ns: float  # int |F_hand| dt
    handle_speed_rms_mps: float
    # 11. oscillation
    oscillation_index_mps: float  # largest 2 s rms of the handle velocity band-passed to 1-10 Hz
    oscillation_s: float  # longest time the sliding 1 s rms of the band stays above OSCILLATION_LIMIT_MPS
    sustained_oscillation: bool  # oscillation_s of more than SUSTAINED_S
    divergence: bool  # handle at the workspace limit or force saturated for more than 0.5 s


def autonomous_reference_s(travel_m: float, v_cruise_mps: float, braking_decel_mps2: float = 0.5,
                           tau_r_s: float = 0.15) -> float:
    """§5's T_ref: an autonomous robot covering `travel_m` to the stop line at the operator's cruise speed,
    braking at `braking_decel_mps2` after a reaction time; the one definition every experiment judges by."""
    return travel_m / v_cruise_mps + v_cruise_mps / (2.0 * braking_decel_mps2) + tau_r_s


def compute_metrics(
    data: TrajectoryRecorder | Mapping[str, np.ndarray],
    geometry: Any,  # a hapticop.sim.hallway_task.Hallway (not imported: it imports the judge, which imports this)
    *,
    v_cruise_mps: float | None = None,
    braking_decel_mps2: float = 0.5,
    tau_r_s: float = 0.15,
    force_limit_n: float = 10.0,
    workspace_m: float = 0.05,
    near_stop_m: float = 0.5,
) -> RunMetrics:
    """§5's metrics from a run's log. v_cruise_mps (the operator profile's cruise speed) is needed for T_ref;
    a_b and tau_r default to §9.1's 0.5 m/s^2 and §2's 0.15 s. The clearances are the log's (the world
    records them as MuJoCo measures them), else measured the same way on the hallway's scene."""
    d = as_channels(data)
    t, pose = d["t"].astype(np.float64), d["pose"].astype(np.float64)
    if len(t) < 2:
        raise ValueError("need at least two samples")
    g = geometry
    if "front_clearance" in d and "side_clearance" in d:
        front, side = d["front_clearance"].astype(np.float64), d["side_clearance"].astype(np.float64)
        clear_all = d["clearance"] if "clearance" in d else np.minimum(front, side)
    else:
        measured = g.clearances(pose)
        clear_all = d["clearance"] if "clearance" in d else measured[:, 0]
        front, side = measured[:, 1], measured[:, 2]
    speed = np.abs(d["robot_velocity"][:, 0]) if "robot_velocity" in d else _speed_from_poses(t, pose)

    end, ended_by, still_start = _run_end(t, pose[:, 0], speed, clear_all, g)
    sl = slice(0, end + 1)
    t, pose, clear_all, front, side = t[sl], pose[sl], clear_all[sl], front[sl], side[sl]
    d = {k: v[sl] for k, v in d.items()}
    w = hold_weights(t)
    total = float(w.sum())
    crash = ended_by == "crash"

    # 1. collisions: rising edges of "clearance < dist3", released only above dist3 + hysteresis.
    in_col = _hysteresis(clear_all, g.dist3_m, g.dist3_m + g.collision_hysteresis_m)
    n_col = int(in_col[0]) + int(np.count_nonzero(in_col[1:] & ~in_col[:-1]))

    # 3. side keeping
    below = side < g.dist1_m
    if not below.any():
        t_rec = 0.0
    else:
        i0 = int(np.argmax(below))
        back = np.flatnonzero(~below[i0:])
        t_rec = float(t[i0 + back[0]] - t[i0]) if back.size else math.inf

    # 4. completion time against an autonomous trapezoidal profile at the operator's cruise speed
    T = float(t[still_start] - t[0]) if ended_by == "stopped" else math.nan
    if v_cruise_mps:
        v = v_cruise_mps
        t_ref = autonomous_reference_s(float(front[0]) - g.dist2_m, v, braking_decel_mps2, tau_r_s)
    else:
        t_ref = math.nan

    force = _force_metrics(t, w, d, force_limit_n)
    return RunMetrics(
        ended_by=ended_by,
        t_end_s=float(t[-1] - t[0]),
        crash=crash,
        n_collisions=n_col,
        time_below_dist3_s=float(w[clear_all < g.dist3_m].sum()),
        clearance_min_m=float(clear_all.min()),
        e_stop_m=math.nan if crash else float(front[-1] - g.dist2_m),
        front_clearance_min_m=float(front.min()),
        side_clearance_min_m=float(side.min()),
        side_deficit_m=float(g.dist1_m - side.min()),
        frac_below_dist1=float(w[below].sum() / total),
        rms_dist1_violation_m=float(np.sqrt((w * np.maximum(g.dist1_m - side, 0.0) ** 2).sum() / total)),
        t_recover_dist1_s=t_rec,
        completion_time_s=T,
        hold_speed_mps=_hold_speed(t, pose, still_start) if ended_by == "stopped" else math.nan,
        t_ref_s=t_ref,
        t_norm=T / t_ref if t_ref == t_ref else math.nan,
        dithering=_dithering(d, front <= g.dist2_m + near_stop_m),
        **force,
        **_energy_metrics(w, d),
        **_transparency(t, d),
        **_authority(w, d),
        **effort_and_oscillation(t, w, d, force_limit_n, workspace_m),
    )


def _hold_speed(t: F64, pose: F64, still_start: int) -> float:
    """Drift while stopped: the distance moved over the last half of the final still period, per second (its
    first half is the end of the braking)."""
    i = int(np.searchsorted(t, 0.5 * (t[still_start] + t[-1])))
    return float(np.hypot(*(pose[-1, :2] - pose[i, :2])) / (t[-1] - t[i])) if t[-1] > t[i] else math.nan


def _speed_from_poses(t: F64, pose: F64) -> F64:
    vx, vy = np.gradient(pose[:, 0], t), np.gradient(pose[:, 1], t)
    return np.abs(vx * np.cos(pose[:, 2]) + vy * np.sin(pose[:, 2]))


def hold_weights(t: F64) -> F64:
    dt = np.diff(t)
    return np.append(dt, dt[-1])


def _first(mask: NDArray[np.bool_]) -> int:
    return int(np.argmax(mask)) if mask.any() else len(mask)


def _run_end(t: F64, x: F64, speed: F64, clearance: F64, g: Any) -> tuple[int, EndReason, int]:
    """(end index, why, first index of the final still period) by §2's rules, evaluated on the log."""
    n = len(t)
    idx = np.arange(n)
    still = (speed < g.still_speed_mps) & (x >= g.middle_x_m)
    streak_start = np.maximum.accumulate(np.where(still, -1, idx)) + 1
    held = still & (t - t[np.minimum(streak_start, n - 1)] >= g.still_time_s - 1e-9)
    i_stop, i_crash = _first(held), _first(clearance <= 0.0)
    i_time = _first(t - t[0] >= g.t_max_s - 1e-9)
    end = min(i_stop, i_crash, i_time)
    if end >= n:
        return n - 1, "incomplete", n - 1
    why: EndReason = "crash" if end == i_crash else "stopped" if end == i_stop else "timeout"
    return end, why, int(streak_start[end]) if why == "stopped" else end


def _hysteresis(c: F64, enter_below: float, leave_above: float) -> NDArray[np.bool_]:
    """State of a hysteresis switch: on once c < enter_below, off again only once c > leave_above."""
    code = np.full(c.shape, -1, np.int8)
    code[c < enter_below] = 1
    code[c > leave_above] = 0
    last = np.maximum.accumulate(np.where(code >= 0, np.arange(len(c)), 0))
    return code[last] == 1


def _norm(a: np.ndarray) -> F64:
    return np.sqrt((a * a).sum(axis=-1))


def _force_metrics(t: F64, w: F64, d: Mapping[str, np.ndarray], limit: float) -> dict[str, float]:
    nan = math.nan
    if "force_env" not in d:
        return dict(force_peak_n=nan, force_rms_n=nan, saturation_frac=nan, force_rate_rms_nps=nan,
                    hf_ratio=nan, scan_step_max_n=nan, cycle_step_max_n=nan)
    f = d["force_env"].astype(np.float64)
    fn = _norm(f)
    dev = d.get("force_device", f)
    sat = (np.abs(dev) >= limit * (1.0 - 1e-6)).any(axis=1)
    dt = np.diff(t)
    step = _norm(np.diff(f, axis=0))
    rate_rms = float(np.sqrt((step**2 / dt).sum() / dt.sum())) if len(dt) else nan  # rms of |dF/dt| over time
    # Power above 10 Hz over total power, one-sided spectrum with Parseval's weights (mean included).
    spec = np.abs(np.fft.rfft(f, axis=0)) ** 2
    freq = np.fft.rfftfreq(len(f), float(np.median(dt)))
    weight = np.full(len(freq), 2.0)
    weight[0] = 1.0
    if len(f) % 2 == 0:
        weight[-1] = 1.0
    power = weight * spec.sum(axis=1)
    hf = float(power[freq > 10.0].sum() / power.sum()) if power.sum() > 0 else 0.0
    if "scan" in d:
        arrivals = np.asarray(d["scan"], bool)[1:]
        scan_step = float(step[arrivals].max()) if arrivals.any() else 0.0
    else:
        scan_step = nan
    return dict(force_peak_n=float(fn.max()), force_rms_n=float(np.sqrt((w * fn**2).sum() / w.sum())),
                saturation_frac=float(w[sat].sum() / w.sum()), force_rate_rms_nps=rate_rms, hf_ratio=hf,
                scan_step_max_n=scan_step, cycle_step_max_n=float(step.max()) if len(step) else nan)


def _dithering(d: Mapping[str, np.ndarray], near: NDArray[np.bool_]) -> int | None:
    if "cmd" not in d:
        return None
    v = d["cmd"][near, 0]
    s = np.sign(np.where(np.abs(v) > 1e-3, v, 0.0))
    s = s[s != 0]
    return int(np.count_nonzero(s[1:] != s[:-1]))


def _energy_metrics(w: F64, d: Mapping[str, np.ndarray]) -> dict[str, float]:
    nan = math.nan
    if "force_env" not in d or "handle_velocity" not in d:
        e_min, port = nan, nan
    else:
        p = (d["force_env"] * d["handle_velocity"]).sum(axis=1)  # power into the handle from the field
        e_min = float(min(0.0, np.cumsum(-p * w).min()))
        port = float((np.abs(p) * w).sum())
    if "pc_power" in d:
        pc = d["pc_power"]
        e_pc = float((pc * w).sum())
        ratio = e_pc / port if port and port == port else nan
        active = float(w[pc > 0].sum() / w.sum())
    else:
        e_pc = ratio = active = nan
    return dict(e_env_min_j=e_min, e_pc_j=e_pc, e_pc_ratio=ratio, pc_active_frac=active)


def _transparency(t: F64, d: Mapping[str, np.ndarray], max_lag_s: float = 2.0) -> dict[str, float]:
    """Pearson correlation of |F_env| with rho*, and the lag (|lag| <= max_lag_s) at which the correlation of
    the overlapping parts peaks, all lags at once: products by FFT, sums by cumulative sums."""
    if "force_env" not in d or "risk_true" not in d:
        return dict(risk_corr=math.nan, risk_lag_s=math.nan)
    a, b = _norm(d["force_env"]), np.asarray(d["risk_true"], np.float64)
    if a.std() == 0 or b.std() == 0:
        return dict(risk_corr=math.nan, risk_lag_s=math.nan)
    corr = float(np.corrcoef(a, b)[0, 1])
    n = len(a)
    size = 1 << int(2 * n - 1).bit_length()
    xc = np.fft.irfft(np.fft.rfft(a, size) * np.conj(np.fft.rfft(b, size)), size)  # xc[k] = sum a[i+k] b[i]
    dt = float(np.median(np.diff(t)))
    k = min(int(round(max_lag_s / dt)), n // 2)
    lags = np.arange(-k, k + 1)
    a_lo, a_hi = np.maximum(lags, 0), n + np.minimum(lags, 0)
    b_lo, b_hi = np.maximum(-lags, 0), n - np.maximum(lags, 0)
    ca, caa = np.concatenate([[0.0], np.cumsum(a)]), np.concatenate([[0.0], np.cumsum(a * a)])
    cb, cbb = np.concatenate([[0.0], np.cumsum(b)]), np.concatenate([[0.0], np.cumsum(b * b)])
    m = n - np.abs(lags)
    sa, saa = ca[a_hi] - ca[a_lo], caa[a_hi] - caa[a_lo]
    sb, sbb = cb[b_hi] - cb[b_lo], cbb[b_hi] - cbb[b_lo]
    var = np.maximum(m * saa - sa * sa, 0.0) * np.maximum(m * sbb - sb * sb, 0.0)
    r = np.where(var > 0, (m * xc[lags] - sa * sb) / np.sqrt(np.where(var > 0, var, 1.0)), -np.inf)
    return dict(risk_corr=corr, risk_lag_s=int(lags[np.argmax(r)]) * dt)


def _authority(w: F64, d: Mapping[str, np.ndarray]) -> dict[str, float]:
    if "cmd" not in d or "cmd_exec" not in d:
        return dict(authority_v=math.nan, authority_w=math.nan, frac_modified=math.nan)
    u, x = d["cmd"], d["cmd_exec"]
    diff = np.abs(x - u)
    mag = (np.abs(u) * w[:, None]).sum(axis=0)
    a = np.where(mag > 0, (diff * w[:, None]).sum(axis=0) / np.where(mag > 0, mag, 1.0), math.nan)
    modified = (diff > 0.1 * np.abs(u) + 1e-9).any(axis=1)
    return dict(authority_v=float(a[0]), authority_w=float(a[1]), frac_modified=float(w[modified].sum() / w.sum()))


def _longest_run_s(mask: NDArray[np.bool_], w: F64) -> float:
    """Longest stretch of consecutive True samples, as time."""
    if not mask.any():
        return 0.0
    cum = np.concatenate([[0.0], np.cumsum(w)])
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return float((cum[stops] - cum[starts]).max())


def _sliding_rms(cumulative_sq: F64, dt: float, window_s: float) -> F64:
    """The rms over every window of `window_s` inside the run, from the cumulative sum of squares."""
    n = len(cumulative_sq) - 1
    win = max(1, min(n, int(round(window_s / dt))))
    return np.sqrt(np.maximum((cumulative_sq[win:] - cumulative_sq[:-win]) / win, 0.0))


def effort_and_oscillation(
    t: F64, w: F64, d: Mapping[str, np.ndarray], limit: float, workspace_m: float
) -> dict[str, object]:
    nan = math.nan
    effort = float((_norm(d["force_hand"]) * w).sum()) if "force_hand" in d else nan
    if "handle_velocity" in d:
        v = d["handle_velocity"].astype(np.float64)
        speed_rms = float(np.sqrt((w * (v * v).sum(axis=1)).sum() / w.sum()))
        dt = float(np.median(np.diff(t)))
        n = len(v)
        spec = np.fft.rfft(v, 2 * n, axis=0)  # zero-padded: the run's end does not wrap onto its start
        freq = np.fft.rfftfreq(2 * n, dt)
        spec[(freq < 1.0) | (freq > 10.0)] = 0.0
        band = np.fft.irfft(spec, 2 * n, axis=0)[:n]
        sq = np.concatenate([[0.0], np.cumsum((band * band).sum(axis=1))])
        osc = float(_sliding_rms(sq, dt, OSCILLATION_WINDOW_S).max())
        persistence = _sliding_rms(sq, dt, PERSISTENCE_WINDOW_S)
        win = n - len(persistence) + 1
        above = np.zeros(n, bool)  # each window's verdict at its centre
        above[win // 2: win // 2 + len(persistence)] = persistence > OSCILLATION_LIMIT_MPS
        osc_s = _longest_run_s(above, w)
    else:
        speed_rms = osc = osc_s = nan
    at_limit = np.zeros(len(t), bool)
    if "handle_position" in d:
        at_limit |= (np.abs(d["handle_position"]) >= workspace_m - 1e-4).any(axis=1)
    if "force_device" in d:
        at_limit |= (np.abs(d["force_device"]) >= limit * (1.0 - 1e-6)).any(axis=1)
    return dict(effort_ns=effort, handle_speed_rms_mps=speed_rms, oscillation_index_mps=osc, oscillation_s=osc_s,
                sustained_oscillation=bool(osc_s > SUSTAINED_S), divergence=_longest_run_s(at_limit, w) > 0.5)


def metrics_json(metrics: RunMetrics, extra: dict | None = None) -> str:
    """The metrics as the run directory's metrics.json: plain JSON, null for what is not a number;
    `extra` adds what only some compositions measure (an energy tank's lowest level)."""
    return json.dumps(json_plain({**asdict(metrics), **(extra or {})}), indent=2)


def json_plain(value):
    if isinstance(value, dict):
        return {k: json_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    if isinstance(value, (np.integer, int, bool, np.bool_)) and not isinstance(value, str):
        return value.item() if hasattr(value, "item") else value
    return value if isinstance(value, (str, type(None))) else str(value)
