"""Smart-wheel kinematics, statics and torque distribution for the ropod (docs/devices/ropod.md §4, §5).

Each of the 4 units is a trailing caster: a pivot at p_i, an axle s behind it, two wheels
d apart. With `U_i = [c, s, x_i s - y_i c]` and `Q_i = [-s, c, x_i c + y_i s]` (c, s of the
pivot angle delta_i) the wheel speeds are `(U_i -+ k Q_i) v / r` with k = d/(2s): the stacked
8x3 Jacobian G(delta). By virtual work the wheel torques give the platform wrench G^T tau,
so one masked normal matrix N = G^T M G serves both directions: the least-squares twist
from the wheel speeds (forward kinematics) and the minimum-norm torques for a wrench
(the pseudo-inverse distribution, the ropod's June-2019 default). Everything is evaluated
on Python floats, once per cycle after `update(delta, enable)` (or `evaluate`); `kinematics.pxd`
types the per-cycle methods for Cython (setup.py; the same bits: tests/test_compiled_kernels.py).

Wheel order: [SW1w1, SW1w2, SW2w1, ..., SW4w2]; w1 is on the unit's +y side. Positive
speed/torque rolls/pushes along the unit's +x (the model convention; the hardware's w2
sign flip is the controller's business).
"""

from __future__ import annotations

from collections.abc import Sequence
from math import cos, hypot, sin

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.ropod.geometry import Geometry

__all__ = ["SmartWheelKinematics", "jacobian", "distribute_qp", "inverse_sym3"]

F64 = NDArray[np.float64]


def inverse_sym3(n00: float, n01: float, n02: float, n11: float, n12: float, n22: float,
                 ) -> tuple[float, float, float, float, float, float, float]:
    """(det, i00, i01, i02, i11, i12, i22): the inverse of a symmetric 3x3 matrix by cofactors, on floats.

    A singular matrix (det == 0) gives a zero inverse: check det."""
    c00 = n11 * n22 - n12 * n12
    c01 = n12 * n02 - n01 * n22
    c02 = n01 * n12 - n11 * n02
    det = n00 * c00 + n01 * c01 + n02 * c02
    inv = 1.0 / det if det else 0.0
    return (det, c00 * inv, c01 * inv, c02 * inv, (n22 * n00 - n02 * n02) * inv, (n02 * n01 - n12 * n00) * inv,
            (n00 * n11 - n01 * n01) * inv)


class SmartWheelKinematics:
    """G(delta) and its masked normal inverse for the current pivot angles; no allocation per cycle.

    The numbers live in Python floats, per unit c, s and the third entries of U_i and Q_i (numpy's
    per-call overhead would cost more than the arithmetic); a unit's two wheel rows are
    (U_i -+ k Q_i) / r, so every map runs unit by unit. The 1 kHz users call the float methods
    (`evaluate`, `twist_of`, `wheel_speeds_into`, `distribute_into`, ...); the array methods and
    the array attributes (G, U, Q, N, N_inv, mask, cos, sin) are the same values for tests and
    set-up, and allocate.
    """

    def __init__(self, geometry: Geometry = Geometry()):
        self.geometry = g = geometry
        n = g.units
        self.units, self.wheels = n, 2 * n
        self._inv_r = 1.0 / g.wheel_radius_m
        self._inv_s = 1.0 / g.caster_offset_m
        self._k = g.k
        # Per unit (ua, ub, qa, qb): U_i = [c, s, ua c + ub s] and Q_i = [-s, c, qa c + qb s].
        self.unit_rows = tuple((-py, px, px, py) for px, py in g.pivots_m)
        self._units = [(1.0, 0.0, 0.0, 0.0, 1.0)] * n  # per unit (c, s, U_i[2], Q_i[2], enabled 0/1)
        self.unit_mask = [1.0] * n  # 0/1 per unit from the enable (read-only)
        self._n = (0.0,) * 6  # N = G^T M G: n00, n01, n02, n11, n12, n22
        self._n_inv = (0.0,) * 6
        self.evaluate([0.0] * n)

    # --- per-cycle evaluation, on floats -------------------------------------------------------
    def evaluate(self, delta: Sequence[float], enable: Sequence[float] | None = None) -> None:
        """U_i, Q_i for the pivot angles, and the normal matrix N = G^T M G and its inverse over the
        units enabled (0/1 each; None: all). A unit adds (2/r^2) (U U^T + k^2 Q Q^T) to N.

        Needs >= 2 enabled units (then N has full rank 3); otherwise raises `np.linalg.LinAlgError`.
        """
        units, mask = self._units, self.unit_mask
        k2 = self._k * self._k
        one_minus_k2 = 1.0 - k2
        n00 = n01 = n02 = n11 = n12 = n22 = 0.0
        for i, (d, (ua, ub, qa, qb)) in enumerate(zip(delta, self.unit_rows)):
            c, s = cos(d), sin(d)
            u3, q3 = c * ua + s * ub, c * qa + s * qb
            on = 1.0 if enable is None or enable[i] else 0.0
            units[i], mask[i] = (c, s, u3, q3, on), on
            if not on:
                continue
            cc, ss = c * c, s * s
            n00 += cc + k2 * ss
            n01 += c * s * one_minus_k2
            n02 += c * u3 - k2 * (s * q3)
            n11 += ss + k2 * cc
            n12 += s * u3 + k2 * (c * q3)
            n22 += u3 * u3 + k2 * (q3 * q3)
        f = 2.0 * self._inv_r * self._inv_r
        n00, n01, n02, n11, n12, n22 = n00 * f, n01 * f, n02 * f, n11 * f, n12 * f, n22 * f
        self._n = (n00, n01, n02, n11, n12, n22)
        det, i00, i01, i02, i11, i12, i22 = inverse_sym3(n00, n01, n02, n11, n12, n22)
        if not det > 1e-12 * (n00 + n11 + n22) ** 3:
            raise np.linalg.LinAlgError("fewer than 2 smart-wheel units enabled: the platform is not controllable")
        self._n_inv = (i00, i01, i02, i11, i12, i22)

    def twist_of(self, wheel_speeds: Sequence[float]) -> tuple[float, float, float]:
        """Forward kinematics: least-squares twist over the enabled units, pinv(M G) M phidot."""
        k = self._k
        a0 = a1 = a2 = 0.0  # G^T M phidot, r times
        for i, (c, s, u3, q3, m) in enumerate(self._units):
            if m:
                p1, p2 = wheel_speeds[2 * i], wheel_speeds[2 * i + 1]
                a, b = p1 + p2, k * (p2 - p1)
                a0 += a * c - b * s
                a1 += a * s + b * c
                a2 += a * u3 + b * q3
        inv_r = self._inv_r
        a0, a1, a2 = a0 * inv_r, a1 * inv_r, a2 * inv_r
        i00, i01, i02, i11, i12, i22 = self._n_inv
        return i00 * a0 + i01 * a1 + i02 * a2, i01 * a0 + i11 * a1 + i12 * a2, i02 * a0 + i12 * a1 + i22 * a2

    def wheel_speeds_into(self, vx: float, vy: float, wz: float, out: list) -> None:
        """Inverse kinematics: the no-slip wheel speeds [rad/s] for a platform twist (unmasked)."""
        k, inv_r = self._k, self._inv_r
        for i, (c, s, u3, q3, _) in enumerate(self._units):
            u, q = c * vx + s * vy + u3 * wz, c * vy - s * vx + q3 * wz
            out[2 * i] = (u - k * q) * inv_r
            out[2 * i + 1] = (u + k * q) * inv_r

    def pivot_rates_into(self, vx: float, vy: float, wz: float, out: list) -> None:
        """The pivot rates delta_dot = q_i/s - wz the twist forces on the trailing casters."""
        inv_s = self._inv_s
        for i, (c, s, _, q3, _) in enumerate(self._units):
            out[i] = (c * vy - s * vx + q3 * wz) * inv_s - wz

    def wrench_of(self, torques: Sequence[float]) -> tuple[float, float, float]:
        """Statics: the platform wrench [Fx, Fy, Mz] at the origin of R from the wheel torques, G^T tau."""
        k, inv_r = self._k, self._inv_r
        fx = fy = mz = 0.0
        for i, (c, s, u3, q3, _) in enumerate(self._units):
            t1, t2 = torques[2 * i], torques[2 * i + 1]
            a, b = t1 + t2, k * (t2 - t1)
            fx += a * c - b * s
            fy += a * s + b * c
            mz += a * u3 + b * q3
        return fx * inv_r, fy * inv_r, mz * inv_r

    def distribute_into(self, fx: float, fy: float, mz: float, tau_max: float, out: list) -> float:
        """Variant A (§5.2): minimum-norm torques pinv(G^T M) w, scaled as a whole to |tau| <= tau_max.

        Returns the scale (1 when the wrench is feasible). Disabled units get zero torque.
        """
        i00, i01, i02, i11, i12, i22 = self._n_inv
        x0, x1, x2 = i00 * fx + i01 * fy + i02 * mz, i01 * fx + i11 * fy + i12 * mz, i02 * fx + i12 * fy + i22 * mz
        k, inv_r = self._k, self._inv_r
        peak = 0.0
        for i, (c, s, u3, q3, m) in enumerate(self._units):
            u, q = c * x0 + s * x1 + u3 * x2, c * x1 - s * x0 + q3 * x2
            t1, t2 = (u - k * q) * inv_r * m, (u + k * q) * inv_r * m
            out[2 * i], out[2 * i + 1] = t1, t2
            if abs(t1) > peak:
                peak = abs(t1)
            if abs(t2) > peak:
                peak = abs(t2)
        if peak > tau_max:
            scale = tau_max / peak
            for j in range(len(out)):
                out[j] *= scale
            return scale
        return 1.0

    def flip_compensate_list(self, torques: list[float], kmax: float, force_threshold: float = 10.0) -> None:
        """§5.4: amplify each unit's differential torque by 1 + (kmax-1)|sin(angle of its pivot force)|
        when its lateral force exceeds the threshold; a no-op for kmax == 1 (normal mode)."""
        if kmax == 1.0:
            return
        inv_r, k = self._inv_r, self._k
        for j in range(0, len(torques), 2):
            t1, t2 = torques[j], torques[j + 1]
            long_, lat = (t1 + t2) * inv_r, (t2 - t1) * (k * inv_r)  # f1 + f2, lambda = k (f2 - f1)
            gain = 1.0
            if not abs(lat) <= force_threshold:
                gain = abs(lat) / max(hypot(long_, lat), 1e-300) * (kmax - 1.0) + 1.0
            common, diff = (t1 + t2) * 0.5, (t2 - t1) * 0.5 * gain
            torques[j], torques[j + 1] = common - diff, common + diff

    @staticmethod
    def clip_per_unit_list(torques: list[float], tau_max: float) -> None:
        """§5.4: scale each unit's torque pair so that neither exceeds tau_max (keeps the pair's ratio)."""
        for j in range(0, len(torques), 2):
            scale = tau_max / max(abs(torques[j]), abs(torques[j + 1]), tau_max)
            torques[j] *= scale
            torques[j + 1] *= scale

    # --- the same on arrays (tests, set-up; allocates) ------------------------------------------
    def update(self, delta: ArrayLike, enable: ArrayLike | None = None) -> None:
        """Evaluate G(delta) and the masked normal inverse; `enable` is 0/1 per unit (default all)."""
        self.evaluate(self._per_unit(delta, "delta"), None if enable is None else self._per_unit(enable, "enable"))

    def update_jacobian(self, delta: ArrayLike) -> None:
        """Evaluate U, Q and G(delta) (with every unit enabled)."""
        self.evaluate(self._per_unit(delta, "delta"))

    def _per_unit(self, values: ArrayLike, what: str) -> list[float]:
        array = np.asarray(values, np.float64)
        if array.shape != (self.units,):
            raise ValueError(f"{what} needs one value per unit ({self.units}), got shape {array.shape}")
        return array.tolist()

    @property
    def cos(self) -> F64:
        return np.array([unit[0] for unit in self._units])

    @property
    def sin(self) -> F64:
        return np.array([unit[1] for unit in self._units])

    @property
    def U(self) -> F64:
        """Along-unit rows of the pivot velocities, (units, 3)."""
        return np.array([(c, s, u3) for c, s, u3, _, _ in self._units])

    @property
    def Q(self) -> F64:
        """Across-unit rows of the pivot velocities, (units, 3)."""
        return np.array([(-s, c, q3) for c, s, _, q3, _ in self._units])

    @property
    def G(self) -> F64:
        """The (wheels, 3) Jacobian: wheel speeds = G twist; unit i's rows are (U_i -+ k Q_i) / r."""
        u, q = self.U, self.Q
        return np.stack([u - self._k * q, u + self._k * q], axis=1).reshape(-1, 3) * self._inv_r

    @property
    def mask(self) -> F64:
        """0/1 per wheel."""
        return np.repeat(self.unit_mask, 2)

    @property
    def N(self) -> F64:
        return _sym3(self._n)

    @property
    def N_inv(self) -> F64:
        return _sym3(self._n_inv)

    def wheel_speeds(self, twist: ArrayLike, out: F64) -> F64:
        """Inverse kinematics: the no-slip wheel speeds [rad/s] for a platform twist (unmasked)."""
        speeds = [0.0] * self.wheels
        self.wheel_speeds_into(*np.asarray(twist, np.float64).tolist(), speeds)
        out[:] = speeds
        return out

    def pivot_rates(self, twist: ArrayLike, out: F64) -> F64:
        """The pivot rates delta_dot = q_i/s - wz the twist forces on the trailing casters."""
        rates = [0.0] * self.units
        self.pivot_rates_into(*np.asarray(twist, np.float64).tolist(), rates)
        out[:] = rates
        return out

    def twist(self, wheel_speeds: ArrayLike, out: F64) -> F64:
        """Forward kinematics: least-squares twist over the enabled units, pinv(M G) M phidot."""
        out[:] = self.twist_of(np.asarray(wheel_speeds, np.float64).tolist())
        return out

    def wrench(self, torques: ArrayLike, out: F64) -> F64:
        """Statics: the platform wrench [Fx, Fy, Mz] at the origin of R from the wheel torques."""
        out[:] = self.wrench_of(np.asarray(torques, np.float64).tolist())
        return out

    def distribute(self, wrench: ArrayLike, tau_max: float, out: F64) -> float:
        """`distribute_into` on arrays."""
        tau = [0.0] * self.wheels
        scale = self.distribute_into(*np.asarray(wrench, np.float64).tolist(), tau_max, tau)
        out[:] = tau
        return scale

    def flip_compensate(self, torques: F64, kmax: float, force_threshold: float = 10.0) -> F64:
        """`flip_compensate_list` on an array, in place."""
        values = torques.tolist()
        self.flip_compensate_list(values, kmax, force_threshold)
        torques[:] = values
        return torques

    def clip_per_unit(self, torques: F64, tau_max: float) -> F64:
        """`clip_per_unit_list` on an array, in place."""
        values = torques.tolist()
        self.clip_per_unit_list(values, tau_max)
        torques[:] = values
        return torques


def _sym3(n: tuple[float, ...]) -> F64:
    n00, n01, n02, n11, n12, n22 = n
    return np.array([[n00, n01, n02], [n01, n11, n12], [n02, n12, n22]])


def jacobian(delta: ArrayLike, geometry: Geometry = Geometry()) -> F64:
    """G(delta), 8x3 (allocates; for tests and set-up)."""
    kin = SmartWheelKinematics(geometry)
    kin.update(np.asarray(delta, np.float64))
    return kin.G.copy()


def distribute_qp(g: ArrayLike, wrench: ArrayLike, enable: ArrayLike, tau_max: float,
                  disabled_weight: float = 1e12, tol: float = 1e-11, max_iter: int = 100) -> tuple[F64, float]:
    """Variant B (§5.3), the ropod 2018/2022 QP; allocates, so it is not for the 1 kHz cycle by default.

    min 1/2 sum h_j tau_j^2 + 1/2 s^2 + f s  s.t.  G^T tau = (1 - s) w, |tau_j| <= tau_max, 0 <= s <= 1,
    with h_j = 1 (enabled) or `disabled_weight`, f = 2 * 8 * tau_max^2. Solved through its 3-variable
    concave dual by a damped (Levenberg-Marquardt) semismooth Newton method. Returns (tau, scale = 1 - s).
    """
    A = np.asarray(g, np.float64).T
    w = np.asarray(wrench, np.float64)
    h = np.where(np.repeat(np.asarray(enable, bool), 2), 1.0, disabled_weight)
    f = 2.0 * A.shape[1] * tau_max**2

    def primal(lam: F64) -> tuple[F64, float]:
        return np.clip(A.T @ lam / h, -tau_max, tau_max), float(np.clip(lam @ w - f, 0.0, 1.0))

    def dual(lam: F64) -> float:
        tau, s = primal(lam)
        return 0.5 * tau @ (h * tau) + 0.5 * s * s + f * s - lam @ (A @ tau + s * w - w)

    size = float(np.trace((A / h) @ A.T)) / 3.0  # scales the damping
    lam = np.linalg.solve((A / h) @ A.T, w)  # the unconstrained (weighted pinv) optimum
    mu, value = 1e-9 * size, dual(lam)
    for _ in range(max_iter):
        tau, s = primal(lam)
        grad = (1.0 - s) * w - A @ tau
        if np.linalg.norm(grad) <= tol * (1.0 + np.linalg.norm(w)):
            break
        free = np.abs(A.T @ lam / h) < tau_max
        hess = (A * (free / h)) @ A.T
        if 0.0 < lam @ w - f < 1.0:
            hess += np.outer(w, w)
        while True:  # Levenberg-Marquardt damping: the dual is only piecewise quadratic
            trial = lam + np.linalg.solve(hess + mu * np.eye(3), grad)
            trial_value = dual(trial)
            if trial_value > value or mu > 1e12 * size:
                break
            mu *= 10.0
        lam, value, mu = trial, trial_value, max(mu / 10.0, 1e-12 * size)
    tau, s = primal(lam)
    return tau, 1.0 - s
