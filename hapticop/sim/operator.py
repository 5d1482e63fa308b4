"""A deterministic blind operator: the felt force in, the force of the hand on the Falcon handle out.

Why: closed-loop runs of the hallway experiment need a repeatable stand-in for a person who cannot see the
robot and only feels the handle (docs/hallway-experiment.md §3; hand models after Hasser & Cutkosky and
Fu & Cavusoglu, reaction delay after McRuer, docs/hallway-experiment.md §3). Three layers:

1. Perception: the operator feels the environmental force F_env(t - tau_h). The centring spring is learned and
   not felt as information, so pass only the environmental part (the rendered force minus the centring PD).
2. Intent, updated at 100 Hz: push forward to z* = -z_c * g(F_z), g(F) = clip(1 - (F - F_slow)/(F_stop - F_slow),
   0, 1); latch STOP (z* = 0 for good) after F_z >= F_stop for 50 ms, or F_z >= F_slow for 1 s while
   |z*| < 0.3 z_c; steer where pushed, x* = clip(G_lat * F_x, +-3 cm). The hand aims at the equilibrium point
   e* = p* (k_h + Kp) / k_h that puts the handle at p* against the device spring Kp, through a first-order
   neuromuscular lag, de/dt = (e* - e) / tau_nm.
3. Hand impedance: F_hand = k_h (e - p) - b_h dp/dt. The hand mass is not a force here: the device simulator
   adds `BlindOperator.mass_kg` to its own moving mass.

Handle axes (the Falcon's device frame, origin at the workspace centre; the same as hapticop.haptics.handle),
assumed here and by the Falcon simulator: x to the operator's right, y up, z towards the operator
(right-handed). Pushing the handle forward, away from the operator, is -z, which the car-driving metaphor maps
to forward speed (thesis §5.3.1), so a felt F_z > 0 resists driving forward. The operator moves the hand along a
felt F_x; which way that turns the robot is the haptic mapping's business. The returned force acts on the handle
in these axes; the Falcon simulator adds it to its motor force and `mass_kg` to its moving mass.

`BlindOperator.step` runs at 1 kHz (or 300 Hz) on plain floats: no numpy array, list or tuple is created.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

SWEEP_RANGES: dict[str, tuple[float, float]] = {
    "k_h_n_per_m": (30.0, 600.0),
    "b_h_ns_per_m": (1.0, 15.0),
    "m_h_kg": (0.2, 1.0),
    "tau_h_s": (0.15, 0.35),
    "z_c_m": (0.010, 0.045),
    "f_slow_n": (0.5, 2.5),
    "f_stop_n": (1.5, 6.0),
    "g_lat_m_per_n": (0.0, 0.008),
}
"""§3's robustness sweep: the box the Latin hypercube of operators is drawn from."""


@dataclass(frozen=True)
class OperatorProfile:
    """The parameters of one synthetic operator (§3's table); the named ones are cautious, nominal, aggressive."""

    name: str
    z_c_m: float  # forward handle displacement aimed for when nothing is felt
    f_slow_n: float  # felt resistance at which the operator starts to ease off
    f_stop_n: float  # felt resistance at which the operator no longer pushes (and, held 50 ms, stops)
    g_lat_m_per_n: float  # lateral handle displacement per felt lateral force
    tau_h_s: float  # reaction delay
    m_h_kg: float  # hand mass, added to the device's mass
    b_h_ns_per_m: float  # hand damping
    k_h_n_per_m: float  # hand (grip) stiffness
    tau_nm_s: float = 0.1  # neuromuscular lag
    lat_max_m: float = 0.03  # the lateral aim saturates here
    bump_s: float = 0.05  # F_z >= F_stop this long latches STOP
    persist_s: float = 1.0  # F_z >= F_slow this long while barely pushing latches STOP
    persist_frac: float = 0.3  # "barely pushing": |z*| below this fraction of z_c

    def __post_init__(self) -> None:
        if not self.f_stop_n > self.f_slow_n:
            raise ValueError(f"{self.name}: f_stop_n ({self.f_stop_n}) must exceed f_slow_n ({self.f_slow_n})")
        if self.k_h_n_per_m <= 0 or self.tau_nm_s <= 0 or self.z_c_m < 0 or self.tau_h_s < 0:
            raise ValueError(f"{self.name}: k_h and tau_nm must be > 0, z_c and tau_h >= 0")

    @classmethod
    def cautious(cls) -> OperatorProfile:
        return cls("cautious", 0.015, 0.5, 2.0, 0.006, 0.20, 0.3, 2.0, 50.0)

    @classmethod
    def nominal(cls) -> OperatorProfile:
        return cls("nominal", 0.025, 1.0, 3.0, 0.006, 0.25, 0.5, 5.0, 200.0)

    @classmethod
    def aggressive(cls) -> OperatorProfile:
        return cls("aggressive", 0.040, 2.0, 5.0, 0.003, 0.30, 0.8, 10.0, 500.0)

    @classmethod
    def named(cls, name: str) -> OperatorProfile:
        makers = {"cautious": cls.cautious, "nominal": cls.nominal, "aggressive": cls.aggressive}
        if name not in makers:
            raise ValueError(f"unknown operator profile {name!r}; expected one of {', '.join(makers)}")
        return makers[name]()

    def cruise_speed(self, k1: float = 28.0, dead_zone_m: float = 0.005) -> float:
        """Robot speed while nothing is felt: k1 * (z_c - dead zone) with a subtractive dead zone (0.56 m/s nominal)."""
        return k1 * max(self.z_c_m - dead_zone_m, 0.0)

    def varied(self, rng: np.random.Generator, spread: float = 0.1) -> OperatorProfile:
        """This operator on another day: every §3 sweep parameter scaled by U(1 - spread, 1 + spread), kept inside
        the sweep box, F_stop kept above F_slow. Same generator state, same operator."""
        draws = rng.uniform(1.0 - spread, 1.0 + spread, size=len(SWEEP_RANGES))
        values = {k: float(np.clip(getattr(self, k) * f, *SWEEP_RANGES[k])) for k, f in zip(SWEEP_RANGES, draws)}
        _order_thresholds(values)
        return replace(self, name=f"{self.name}~", **values)

    @staticmethod
    def sweep(n: int, rng: np.random.Generator) -> list[OperatorProfile]:
        """§3's robustness sweep: a seeded Latin hypercube of n operators over SWEEP_RANGES.

        The F_slow and F_stop ranges overlap; where a draw gives F_stop < F_slow the two are swapped (both values
        then lie in [1.5, 2.5] N, inside both ranges), so each parameter keeps its strata.
        """
        keys = list(SWEEP_RANGES)
        u = (rng.permuted(np.tile(np.arange(n), (len(keys), 1)), axis=1).T + rng.random((n, len(keys)))) / n
        out = []
        for i in range(n):
            values = {k: lo + (hi - lo) * float(u[i, j]) for j, (k, (lo, hi)) in enumerate(SWEEP_RANGES.items())}
            _order_thresholds(values)
            out.append(OperatorProfile(name=f"sweep{i:03d}", **values))
        return out


def _order_thresholds(values: dict[str, float]) -> None:
    lo, hi = sorted((values["f_slow_n"], values["f_stop_n"]))
    values["f_slow_n"], values["f_stop_n"] = lo, max(hi, lo + 0.05)


@dataclass(frozen=True)
class Tremor:
    """§3's tremor add-on: a 9 Hz, 0.3 mm sinusoid plus seeded 1/f noise of 0.2 mm rms, on x and z.

    Tremor bypasses the voluntary (neuromuscular-lag) path; it is added to the hand's equilibrium point, scaled so
    that the quasi-static handle displacement has the stated amplitude.
    """

    freq_hz: float = 9.0
    amplitude_m: float = 0.3e-3
    pink_rms_m: float = 0.2e-3
    seed: int = 0


def pink_noise(n: int, rate_hz: float, rms: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """n samples of zero-mean 1/f (pink) noise with the given rms: white noise shaped by 1/sqrt(f) in frequency."""
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    spec[0] = 0.0
    spec[1:] /= np.sqrt(f[1:])
    x = np.fft.irfft(spec, n)
    std = x.std()
    return x * (rms / std) if std > 0 else x


class BlindOperator:
    """One synthetic operator's hand on the handle; call `step` every servo cycle with a rising time.

    Variants of §3/§6 via `BlindOperator.variant`: "cautious", "nominal", "aggressive", "tremor" (nominal plus
    tremor) and "hands_off" (nominal, lets go at t = 5 s for 2 s; on re-gripping the hand starts where the handle
    is). `done` is the operator's own belief that the task is over: STOP latched and held for `done_hold_s`, or
    the time limit. The run's end for the metrics is the robot-side rule of §2, not this.
    """

    GRID_S = 0.001  # the felt force is sampled on this grid for the reaction delay
    RULE_S = 0.01  # intent rules run at 100 Hz

    def __init__(
        self,
        profile: OperatorProfile,
        *,
        kp_device: float = 55.0,
        t_max_s: float = 90.0,
        done_hold_s: float = 2.0,
        tremor: Tremor | None = None,
        hands_off: tuple[float, float] | None = None,
    ):
        self.profile = profile
        self.kp_device = kp_device
        self.t_max_s = t_max_s
        self.done_hold_s = done_hold_s
        self.tremor = tremor
        self.hands_off = hands_off
        p = profile
        self._gain = (p.k_h_n_per_m + kp_device) / p.k_h_n_per_m  # handle aim -> equilibrium-point aim
        self._delay_slots = int(round(p.tau_h_s / self.GRID_S))
        self._cap = self._delay_slots + 1
        self._buf_x = [0.0] * self._cap
        self._buf_z = [0.0] * self._cap
        if tremor is not None:
            rng = np.random.default_rng(tremor.seed)
            self._tremor_phase = [float(v) for v in rng.uniform(0.0, 2.0 * math.pi, 2)]
            n = int(math.ceil(t_max_s / self.RULE_S)) + 2
            self._pink_x = [float(v) for v in pink_noise(n, 1.0 / self.RULE_S, tremor.pink_rms_m, rng)]
            self._pink_z = [float(v) for v in pink_noise(n, 1.0 / self.RULE_S, tremor.pink_rms_m, rng)]
        self.reset()

    @classmethod
    def variant(cls, name: str, seed: int | None = None, **kwargs: object) -> BlindOperator:
        """One of the five §6 operator variants; with a seed, the profile is `varied` by that seed."""
        base = "nominal" if name in ("tremor", "hands_off") else name
        profile = OperatorProfile.named(base)
        if seed is not None:
            profile = profile.varied(np.random.default_rng(seed))
        if name == "tremor":
            kwargs.setdefault("tremor", Tremor(seed=0 if seed is None else seed))
        elif name == "hands_off":
            kwargs.setdefault("hands_off", (5.0, 2.0))
        return cls(profile, **kwargs)  # type: ignore[arg-type]

    def reset(self) -> None:
        """Back to the start of a run: hand relaxed at the origin, nothing felt, no STOP."""
        for i in range(self._cap):
            self._buf_x[i] = 0.0
            self._buf_z[i] = 0.0
        self._w = 0
        self._t0 = math.nan
        self._t_prev = math.nan
        self._grid_k = 0
        self._rule_k = 0
        self._px = self._py = self._pz = 0.0
        self._ex = self._ey = self._ez = 0.0
        self._xs = 0.0
        self._zs = 0.0
        self._bump_since = math.nan
        self._persist_since = math.nan
        self.stopped = False
        self.t_stop = math.nan
        self.holding = True
        self.felt_x = 0.0  # the delayed force the rules last used
        self.felt_z = 0.0

    @property
    def intent(self) -> tuple[float, float]:
        """Where the operator wants the handle: (x*, z*) in m."""
        return self._xs, self._zs

    @property
    def mass_kg(self) -> float:
        """Hand mass the device simulator must add to its own (0 while hands-off)."""
        return self.profile.m_h_kg if self.holding else 0.0

    def done(self, t: float) -> bool:
        return t >= self.t_max_s or (self.stopped and t - self.t_stop >= self.done_hold_s)

    def step(
        self,
        t: float,
        force_felt: NDArray[np.floating],
        position: NDArray[np.floating],
        out: NDArray[np.float64],
        velocity: NDArray[np.floating] | None = None,
    ) -> NDArray[np.float64]:
        """Write the hand's force on the handle (3,) into out, for time t [s], the environmental force (3,) on
        the handle now, and the handle position (3,) [m]; velocity (3,) defaults to a backward difference."""
        p = self.profile
        px, py, pz = float(position[0]), float(position[1]), float(position[2])
        first = self._t0 != self._t0  # NaN: first call
        if first:
            self._t0 = t
            self._t_prev = t
            self._px, self._py, self._pz = px, py, pz
        dt = t - self._t_prev
        if velocity is not None:
            vx, vy, vz = float(velocity[0]), float(velocity[1]), float(velocity[2])
        elif dt > 0.0:
            vx, vy, vz = (px - self._px) / dt, (py - self._py) / dt, (pz - self._pz) / dt
        else:
            vx = vy = vz = 0.0
        self._px, self._py, self._pz = px, py, pz
        self._t_prev = t

        holding = self.hands_off is None or not (
            self.hands_off[0] <= t < self.hands_off[0] + self.hands_off[1]
        )
        if holding and not self.holding:  # grips again where the handle is
            self._ex, self._ey, self._ez = px, py, pz
        self.holding = holding
        fx = float(force_felt[0]) if holding else 0.0
        fz = float(force_felt[2]) if holding else 0.0

        # Perception: the felt force on a 1 ms grid, read tau_h later.
        rel = t - self._t0 + 1e-9
        while self._grid_k * self.GRID_S <= rel:
            self._buf_x[self._w] = fx
            self._buf_z[self._w] = fz
            self._w = (self._w + 1) % self._cap
            self._grid_k += 1
        if self._rule_k * self.RULE_S <= rel:
            self._update_intent(t)
            while self._rule_k * self.RULE_S <= rel:
                self._rule_k += 1

        # Neuromuscular lag towards the equilibrium point that puts the handle at the aim.
        if dt > 0.0:
            a = 1.0 - math.exp(-dt / p.tau_nm_s)
            self._ex += (self._gain * self._xs - self._ex) * a
            self._ey += (0.0 - self._ey) * a
            self._ez += (self._gain * self._zs - self._ez) * a
        if not holding:
            out[0] = out[1] = out[2] = 0.0
            return out
        ex, ez = self._ex, self._ez
        if self.tremor is not None:
            tr = self.tremor
            rel = t - self._t0
            k = rel / self.RULE_S
            i = int(k)
            if i + 1 < len(self._pink_x):
                f = k - i
                ex += self._gain * (tr.amplitude_m * math.sin(2.0 * math.pi * tr.freq_hz * rel + self._tremor_phase[0])
                                    + self._pink_x[i] + f * (self._pink_x[i + 1] - self._pink_x[i]))
                ez += self._gain * (tr.amplitude_m * math.sin(2.0 * math.pi * tr.freq_hz * rel + self._tremor_phase[1])
                                    + self._pink_z[i] + f * (self._pink_z[i + 1] - self._pink_z[i]))
        k_h, b_h = p.k_h_n_per_m, p.b_h_ns_per_m
        out[0] = k_h * (ex - px) - b_h * vx
        out[1] = k_h * (self._ey - py) - b_h * vy
        out[2] = k_h * (ez - pz) - b_h * vz
        return out

    def _update_intent(self, t: float) -> None:
        """The 100 Hz rules of §3 on the force felt tau_h ago (the oldest slot of the delay line)."""
        p = self.profile
        fx = self._buf_x[self._w]
        fz = self._buf_z[self._w]
        self.felt_x, self.felt_z = fx, fz
        if not self.stopped:
            g = 1.0 - (fz - p.f_slow_n) / (p.f_stop_n - p.f_slow_n)
            g = 0.0 if g < 0.0 else 1.0 if g > 1.0 else g
            zs = -p.z_c_m * g
            if fz >= p.f_stop_n:
                if self._bump_since != self._bump_since:
                    self._bump_since = t
            else:
                self._bump_since = math.nan
            if fz >= p.f_slow_n and abs(zs) < p.persist_frac * p.z_c_m:
                if self._persist_since != self._persist_since:
                    self._persist_since = t
            else:
                self._persist_since = math.nan
            eps = 1e-9
            if t - self._bump_since >= p.bump_s - eps or t - self._persist_since >= p.persist_s - eps:
                self.stopped = True
                self.t_stop = t
                zs = 0.0
            self._zs = zs
        xs = p.g_lat_m_per_n * fx
        self._xs = -p.lat_max_m if xs < -p.lat_max_m else p.lat_max_m if xs > p.lat_max_m else xs
