"""The hallway experiment's log, its metrics (docs/hallway-experiment.md §5) and the targets they are judged by (§6).

Why: every condition of §4 is compared on the same deterministic numbers, computed after the run from what a
1 kHz loop recorded. `TrajectoryRecorder` is that record: preallocated, appended to without allocating, saved
as .npz. `compute_metrics` turns it into `RunMetrics`; `targets_met` checks them against `Targets`.

Metrics that need a channel the run did not record come out NaN (or None) and their target is "not measured".
Time-weighted quantities weight each sample by the interval to the next one (sample and hold).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.sim.hallway import HallwayGeometry, World

F64 = NDArray[np.float64]

CHANNELS: dict[str, tuple[tuple[int, ...], type]] = {
    "t": ((), np.float64),  # time [s]
    "pose": ((3,), np.float64),  # robot x, y [m], theta [rad], world frame
    "robot_velocity": ((2,), np.float64),  # measured v [m/s], omega [rad/s]
    "cmd": ((2,), np.float64),  # the operator's command u_cmd = (v, omega) from the handle
    "cmd_exec": ((2,), np.float64),  # the command executed after the safety layer, u_exec
    "handle_position": ((3,), np.float64),  # Falcon handle p [m], device frame
    "handle_velocity": ((3,), np.float64),  # dp/dt [m/s]
    "force_env": ((3,), np.float64),  # environmental force F_env on the handle [N]
    "force_hand": ((3,), np.float64),  # the hand's force on the handle [N]
    "force_device": ((3,), np.float64),  # the whole force sent to the device, after saturation [N]
    "clearance": ((), np.float64),  # footprint clearance to all walls [m]
    "pc_power": ((), np.float64),  # power the passivity controller dissipates [W]
    "scan": ((), np.bool_),  # a new scan reached the force model in this cycle
    "risk_true": ((), np.float64),  # ground-truth risk rho* from the undelayed true state
}
"""What a run may log. A channel is logged every cycle or never: only "t" and "pose" are required."""


class TrajectoryRecorder:
    """A run's log in arrays of fixed capacity; `append` copies one cycle in and allocates nothing.

    A full recorder drops further samples and counts them in `dropped` rather than raising in a real-time loop.
    """

    def __init__(self, capacity: int, meta: Mapping[str, object] | None = None):
        if capacity < 1:
            raise ValueError("capacity must be at least one sample")
        self.capacity = capacity
        self.meta: dict[str, object] = dict(meta or {})
        self.n = 0
        self.dropped = 0
        self._data = {k: np.zeros((capacity, *shape), dtype) for k, (shape, dtype) in CHANNELS.items()}
        self._written = {k: k in ("t", "pose") for k in CHANNELS}
        d = self._data
        self.t, self.pose, self.robot_velocity = d["t"], d["pose"], d["robot_velocity"]
        self.cmd, self.cmd_exec = d["cmd"], d["cmd_exec"]
        self.handle_position, self.handle_velocity = d["handle_position"], d["handle_velocity"]
        self.force_env, self.force_hand, self.force_device = d["force_env"], d["force_hand"], d["force_device"]
        self.clearance, self.pc_power, self.scan, self.risk_true = (
            d["clearance"], d["pc_power"], d["scan"], d["risk_true"])

    def append(
        self,
        t: float,
        pose: ArrayLike,
        *,
        robot_velocity: ArrayLike | None = None,
        cmd: ArrayLike | None = None,
        cmd_exec: ArrayLike | None = None,
        handle_position: ArrayLike | None = None,
        handle_velocity: ArrayLike | None = None,
        force_env: ArrayLike | None = None,
        force_hand: ArrayLike | None = None,
        force_device: ArrayLike | None = None,
        clearance: float | None = None,
        pc_power: float | None = None,
        scan: bool | None = None,
        risk_true: float | None = None,
    ) -> bool:
        """Copy one cycle in; False (and `dropped` + 1) when full."""
        i = self.n
        if i >= self.capacity:
            self.dropped += 1
            return False
        w = self._written
        self.t[i] = t
        self.pose[i] = pose
        if robot_velocity is not None:
            self.robot_velocity[i] = robot_velocity
            w["robot_velocity"] = True
        if cmd is not None:
            self.cmd[i] = cmd
            w["cmd"] = True
        if cmd_exec is not None:
            self.cmd_exec[i] = cmd_exec
            w["cmd_exec"] = True
        if handle_position is not None:
            self.handle_position[i] = handle_position
            w["handle_position"] = True
        if handle_velocity is not None:
            self.handle_velocity[i] = handle_velocity
            w["handle_velocity"] = True
        if force_env is not None:
            self.force_env[i] = force_env
            w["force_env"] = True
        if force_hand is not None:
            self.force_hand[i] = force_hand
            w["force_hand"] = True
        if force_device is not None:
            self.force_device[i] = force_device
            w["force_device"] = True
        if clearance is not None:
            self.clearance[i] = clearance
            w["clearance"] = True
        if pc_power is not None:
            self.pc_power[i] = pc_power
            w["pc_power"] = True
        if scan is not None:
            self.scan[i] = scan
            w["scan"] = True
        if risk_true is not None:
            self.risk_true[i] = risk_true
            w["risk_true"] = True
        self.n = i + 1
        return True

    def arrays(self) -> dict[str, np.ndarray]:
        """Views of the recorded part of every channel that was written."""
        return {k: a[: self.n] for k, a in self._data.items() if self._written[k]}

    def save(self, path: str | Path) -> Path:
        """Write the recorded channels and `meta` (as JSON) to a compressed .npz."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        np.savez_compressed(path, __meta__=np.array(json.dumps(self.meta)), **self.arrays())
        return path

    @classmethod
    def load(cls, path: str | Path, capacity: int | None = None) -> TrajectoryRecorder:
        """Read a saved log back; capacity defaults to the number of samples in it."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["__meta__"]))
            arrays = {k: z[k] for k in z.files if k != "__meta__"}
        unknown = set(arrays) - set(CHANNELS)
        if unknown:
            raise ValueError(f"{path}: unknown channels {sorted(unknown)}")
        n = len(arrays["t"])
        rec = cls(max(capacity or n, n, 1), meta)
        for k, a in arrays.items():
            rec._data[k][:n] = a
            rec._written[k] = True
        rec.n = n
        return rec


def as_channels(data: TrajectoryRecorder | Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The logged channels of a recorder, or of a mapping such as a loaded .npz (other keys are ignored)."""
    if isinstance(data, TrajectoryRecorder):
        return data.arrays()
    return {k: np.asarray(data[k]) for k in data.keys() if k in CHANNELS}


EndReason = Literal["stopped", "crash", "timeout", "incomplete"]


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
    t_ref_s: float  # travel / v_cruise + v_cruise / (2 a_b) + tau_r
    t_norm: float
    # 5. peak force and saturation
    force_peak_n: float  # max |F_env|
    force_rms_n: float  # rms |F_env|
    saturation_frac: float  # time with any axis of the device force (or F_env) at the limit
    # 6. smoothness
    force_rate_rms_nps: float  # rms |dF_env/dt|
    hf_ratio: float  # power of F_env above 10 Hz / total power (mean included)
    scan_step_max_n: float  # largest |F_env| step in a cycle where a scan arrived
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
    sustained_oscillation: bool  # oscillation index above 2 cm/s
    divergence: bool  # handle at the workspace limit or force saturated for more than 0.5 s


def compute_metrics(
    data: TrajectoryRecorder | Mapping[str, np.ndarray],
    geometry: HallwayGeometry,
    *,
    v_cruise_mps: float | None = None,
    braking_decel_mps2: float = 0.5,
    tau_r_s: float = 0.15,
    force_limit_n: float = 10.0,
    workspace_m: float = 0.05,
    near_stop_m: float = 0.5,
    world: World | None = None,
) -> RunMetrics:
    """§5's metrics from a run's log. v_cruise_mps (the operator profile's cruise speed) is needed for T_ref;
    a_b and tau_r default to §9.1's 0.5 m/s^2 and §2's 0.15 s."""
    d = as_channels(data)
    t, pose = d["t"].astype(np.float64), d["pose"].astype(np.float64)
    if len(t) < 2:
        raise ValueError("need at least two samples")
    g = geometry
    world = world or World.from_geometry(g)
    fp = g.footprint
    clear_all = d["clearance"] if "clearance" in d else world.clearances(pose, fp)
    front = world.clearances(pose, fp, kinds=("end",))
    side = world.clearances(pose, fp, kinds=("side", "pillar"))
    speed = np.abs(d["robot_velocity"][:, 0]) if "robot_velocity" in d else _speed_from_poses(t, pose)

    end, ended_by, still_start = _run_end(t, pose[:, 0], speed, clear_all, g)
    sl = slice(0, end + 1)
    t, pose, clear_all, front, side = t[sl], pose[sl], clear_all[sl], front[sl], side[sl]
    d = {k: v[sl] for k, v in d.items()}
    w = _hold_weights(t)
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
        t_ref = (float(front[0]) - g.dist2_m) / v + v / (2.0 * braking_decel_mps2) + tau_r_s
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
        t_ref_s=t_ref,
        t_norm=T / t_ref if t_ref == t_ref else math.nan,
        dithering=_dithering(d, front <= g.dist2_m + near_stop_m),
        **force,
        **_energy_metrics(w, d),
        **_transparency(t, d),
        **_authority(w, d),
        **_effort_and_oscillation(t, w, d, force_limit_n, workspace_m),
    )


def _speed_from_poses(t: F64, pose: F64) -> F64:
    vx, vy = np.gradient(pose[:, 0], t), np.gradient(pose[:, 1], t)
    return np.abs(vx * np.cos(pose[:, 2]) + vy * np.sin(pose[:, 2]))


def _hold_weights(t: F64) -> F64:
    dt = np.diff(t)
    return np.append(dt, dt[-1])


def _first(mask: NDArray[np.bool_]) -> int:
    return int(np.argmax(mask)) if mask.any() else len(mask)


def _run_end(t: F64, x: F64, speed: F64, clearance: F64, g: HallwayGeometry) -> tuple[int, EndReason, int]:
    """(end index, why, first index of the final still period) by §2's rules, evaluated on the log."""
    n = len(t)
    idx = np.arange(n)
    still = (speed < g.still_speed_mps) & (x >= 0.5 * (g.entrance_x_m + g.length_m))
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
                    hf_ratio=nan, scan_step_max_n=nan)
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
                scan_step_max_n=scan_step)


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


def _effort_and_oscillation(
    t: F64, w: F64, d: Mapping[str, np.ndarray], limit: float, workspace_m: float
) -> dict[str, object]:
    nan = math.nan
    effort = float((_norm(d["force_hand"]) * w).sum()) if "force_hand" in d else nan
    if "handle_velocity" in d:
        v = d["handle_velocity"].astype(np.float64)
        speed_rms = float(np.sqrt((w * (v * v).sum(axis=1)).sum() / w.sum()))
        dt = float(np.median(np.diff(t)))
        spec = np.fft.rfft(v, axis=0)
        freq = np.fft.rfftfreq(len(v), dt)
        spec[(freq < 1.0) | (freq > 10.0)] = 0.0
        band = np.fft.irfft(spec, len(v), axis=0)
        sq = np.concatenate([[0.0], np.cumsum((band * band).sum(axis=1))])
        win = max(1, min(len(v), int(round(2.0 / dt))))
        osc = float(np.sqrt(max(((sq[win:] - sq[:-win]) / win).max(), 0.0)))
    else:
        speed_rms = osc = nan
    at_limit = np.zeros(len(t), bool)
    if "handle_position" in d:
        at_limit |= (np.abs(d["handle_position"]) >= workspace_m - 1e-4).any(axis=1)
    if "force_device" in d:
        at_limit |= (np.abs(d["force_device"]) >= limit * (1.0 - 1e-6)).any(axis=1)
    return dict(effort_ns=effort, handle_speed_rms_mps=speed_rms, oscillation_index_mps=osc,
                sustained_oscillation=bool(osc > 0.02), divergence=_longest_run_s(at_limit, w) > 0.5)


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
