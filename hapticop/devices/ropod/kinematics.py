"""Smart-wheel kinematics, statics and torque distribution for the ropod (ropod-controller.md §4, §5).

Each of the 4 units is a trailing caster: a pivot at p_i, an axle s behind it, two wheels
d apart. With `U_i = [c, s, x_i s - y_i c]` and `Q_i = [-s, c, x_i c + y_i s]` (c, s of the
pivot angle delta_i) the wheel speeds are `(U_i -+ k Q_i) v / r` with k = d/(2s): the stacked
8x3 Jacobian G(delta). By virtual work the wheel torques give the platform wrench G^T tau,
so one masked normal matrix N = G^T M G serves both directions: the least-squares twist
from the wheel speeds (forward kinematics) and the minimum-norm torques for a wrench
(the pseudo-inverse distribution, the ropod's June-2019 default). Everything is evaluated
in place on preallocated arrays, once per cycle after `update(delta, enable)`.

Wheel order: [SW1w1, SW1w2, SW2w1, ..., SW4w2]; w1 is on the unit's +y side. Positive
speed/torque rolls/pushes along the unit's +x (the model convention; the hardware's w2
sign flip is the controller's business).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Geometry", "SmartWheelKinematics", "jacobian", "distribute_qp", "Inverse3"]

F64 = NDArray[np.float64]

# Flat indices of the cyclic cofactor formula cof[i, j] = a[i+1, j+1] a[i+2, j+2] - a[i+1, j+2] a[i+2, j+1].
_R1 = (np.arange(3)[:, None] + 1) % 3
_R2 = (np.arange(3)[:, None] + 2) % 3
_C1 = (np.arange(3)[None, :] + 1) % 3
_C2 = (np.arange(3)[None, :] + 2) % 3
# Ordered [P, R, Q, S] so that cof = t[0] t[2] - t[1] t[3]; transposed, so the take yields adj(a).
_ADJ = np.ascontiguousarray(np.stack([3 * r + c for r, c in ((_R1, _C1), (_R1, _C2), (_R2, _C2), (_R2, _C1))])
                            .transpose(0, 2, 1))


class Inverse3:
    """In-place inverse of a 3x3 matrix by cofactors: numpy's inv/solve allocate on every call."""

    def __init__(self) -> None:
        t = self._t = np.zeros((4, 3, 3))
        p = self._p = np.zeros((2, 3, 3))
        self._t_lo, self._t_hi, self._p0, self._p1 = t[:2], t[2:], p[0], p[1]
        self._cof_t = np.zeros((3, 3))  # transposed cofactors (the adjugate)
        self._col0 = self._cof_t[:, 0]

    def __call__(self, a: F64, out: F64) -> float:
        """out = inv(a) for a C-contiguous (3, 3) float64 `a`; returns det(a)."""
        a.reshape(9).take(_ADJ, out=self._t, mode="wrap")
        np.multiply(self._t_lo, self._t_hi, out=self._p)
        np.subtract(self._p0, self._p1, out=self._cof_t)
        det = float(a[0].dot(self._col0))
        np.multiply(self._cof_t, 1.0 / det, out=out)
        return det


@dataclass(frozen=True)
class Geometry:
    """Ropod geometry as compiled in the June-2019 controller (ropod-controller.md §2.2), in metres.

    Pivots SW1..SW4 counter-clockwise from front-left; the order is a known open question (§10 Q1).
    """

    wheel_radius_m: float = 0.0525
    caster_offset_m: float = 0.01
    wheel_distance_m: float = 0.08
    pivots_m: tuple[tuple[float, float], ...] = ((0.21, 0.21), (-0.21, 0.21), (-0.21, -0.21), (0.21, -0.21))

    @property
    def units(self) -> int:
        return len(self.pivots_m)

    @property
    def wheels(self) -> int:
        return 2 * len(self.pivots_m)

    @property
    def k(self) -> float:
        """Lateral-to-differential lever d/(2s): moving across a unit costs k times the wheel speed."""
        return self.wheel_distance_m / (2.0 * self.caster_offset_m)


class SmartWheelKinematics:
    """G(delta) and its masked normal inverse for the current pivot angles; no allocation per cycle."""

    def __init__(self, geometry: Geometry = Geometry()):
        self.geometry = g = geometry
        n = g.units
        self._px = np.array([p[0] for p in g.pivots_m], np.float64)
        self._py = np.array([p[1] for p in g.pivots_m], np.float64)
        self._inv_r = 1.0 / g.wheel_radius_m
        self._inv_s = 1.0 / g.caster_offset_m
        # Rows of U, Q and G are linear in [cos, sin] of the pivot angle: per unit, [c, s] @ coefficients.
        uq = np.zeros((n, 2, 6))
        uq[:, 0, 0], uq[:, 1, 1], uq[:, 0, 2], uq[:, 1, 2] = 1.0, 1.0, -self._py, self._px  # U
        uq[:, 1, 3], uq[:, 0, 4], uq[:, 0, 5], uq[:, 1, 5] = -1.0, 1.0, self._px, self._py  # Q
        gc = np.concatenate([uq[:, :, :3] - g.k * uq[:, :, 3:], uq[:, :, :3] + g.k * uq[:, :, 3:]], axis=2)
        self._uq_coef, self._g_coef = uq, gc * self._inv_r
        self._cs = np.zeros((n, 1, 2))
        self.cos = self._cs[:, 0, 0]
        self.sin = self._cs[:, 0, 1]
        self._uq = np.zeros((n, 1, 6))
        self.U = self._uq[:, 0, :3]  # along-unit row of the pivot velocity
        self.Q = self._uq[:, 0, 3:]  # across-unit row of the pivot velocity
        self.G = np.zeros((2 * n, 3))
        self._G3 = self.G.reshape(n, 1, 6)
        self.mask = np.ones(2 * n)  # per wheel, 0/1 from the unit enable
        self._mask2 = self.mask.reshape(-1, 2)
        self._mask_col = self.mask[:, None]
        self._Gm = np.zeros((2 * n, 3))  # M G
        self._GmT, self._GT = self._Gm.T, self.G.T
        self.N = np.zeros((3, 3))
        self.N_inv = np.zeros((3, 3))
        self._inverse3 = Inverse3()
        self._v3 = np.zeros(3)
        self._u4 = np.zeros(n)
        self._w4 = np.zeros(n)
        self._x4 = np.zeros(n)
        self._b4 = np.zeros(n, bool)
        self._abs8 = np.zeros(2 * n)
        self.update(np.zeros(n))

    # --- per-cycle evaluation -------------------------------------------------------------
    def update(self, delta: ArrayLike, enable: ArrayLike | None = None) -> None:
        """Evaluate G(delta) and the masked normal inverse; `enable` is 0/1 per unit (default all).

        Needs >= 2 enabled units (then N has full rank 3); otherwise raises `np.linalg.LinAlgError`.
        """
        self.update_jacobian(delta)
        m2 = self._mask2
        if enable is None:
            m2.fill(1.0)
        else:
            m2[:, 0] = enable
            m2[:, 1] = enable
        np.multiply(self.G, self._mask_col, out=self._Gm)
        np.matmul(self._GmT, self.G, out=self.N)
        det = self._inverse3(self.N, self.N_inv)
        n = self.N
        if not det > 1e-12 * float(n[0, 0] + n[1, 1] + n[2, 2]) ** 3:
            raise np.linalg.LinAlgError("fewer than 2 smart-wheel units enabled: the platform is not controllable")

    def update_jacobian(self, delta: ArrayLike) -> None:
        """Evaluate U, Q and G(delta) only (what a simulator needs)."""
        np.cos(delta, out=self.cos)
        np.sin(delta, out=self.sin)
        np.matmul(self._cs, self._uq_coef, out=self._uq)
        np.matmul(self._cs, self._g_coef, out=self._G3)

    # --- maps ---------------------------------------------------------------------------
    def wheel_speeds(self, twist: ArrayLike, out: F64) -> F64:
        """Inverse kinematics: the 8 no-slip wheel speeds [rad/s] for a platform twist (unmasked)."""
        return np.matmul(self.G, twist, out=out)

    def pivot_rates(self, twist: ArrayLike, out: F64) -> F64:
        """The 4 pivot rates delta_dot = q_i/s - wz the twist forces on the trailing casters."""
        np.matmul(self.Q, twist, out=out)
        out *= self._inv_s
        out -= twist[2]
        return out

    def twist(self, wheel_speeds: ArrayLike, out: F64) -> F64:
        """Forward kinematics: least-squares twist over the enabled units, pinv(M G) M phidot."""
        np.matmul(self._GmT, wheel_speeds, out=self._v3)
        return np.matmul(self.N_inv, self._v3, out=out)

    def wrench(self, torques: ArrayLike, out: F64) -> F64:
        """Statics: the platform wrench [Fx, Fy, Mz] at the origin of R from 8 wheel torques."""
        return np.matmul(self._GT, torques, out=out)

    def distribute(self, wrench: ArrayLike, tau_max: float, out: F64) -> float:
        """Variant A (§5.2): minimum-norm torques pinv(G^T M) w, scaled as a whole to |tau| <= tau_max.

        Returns the scale (1 when the wrench is feasible). Disabled units get zero torque.
        """
        np.matmul(self.N_inv, wrench, out=self._v3)
        np.matmul(self._Gm, self._v3, out=out)
        peak = float(np.abs(out, out=self._abs8).max())
        if peak > tau_max:
            scale = tau_max / peak
            out *= scale
            return scale
        return 1.0

    def flip_compensate(self, torques: F64, kmax: float, force_threshold: float = 10.0) -> F64:
        """§5.4: amplify each unit's differential torque by 1 + (kmax-1)|sin(angle of its pivot force)|
        when its lateral force exceeds the threshold; a no-op for kmax == 1 (normal mode)."""
        if kmax == 1.0:
            return torques
        t2 = torques.reshape(-1, 2)
        long_, lat, gain = self._u4, self._w4, self._x4
        np.add(t2[:, 0], t2[:, 1], out=long_)
        long_ *= self._inv_r  # f1 + f2
        np.subtract(t2[:, 1], t2[:, 0], out=lat)
        lat *= self.geometry.k * self._inv_r  # lambda = k (f2 - f1)
        np.hypot(long_, lat, out=gain)
        np.maximum(gain, 1e-300, out=gain)
        np.divide(np.abs(lat, out=long_), gain, out=gain)  # |sin(angle)|
        gain *= kmax - 1.0
        gain += 1.0
        np.less_equal(long_, force_threshold, out=self._b4)  # long_ now holds |lambda|
        np.copyto(gain, 1.0, where=self._b4)
        np.subtract(t2[:, 1], t2[:, 0], out=lat)  # 2 * differential torque
        lat *= 0.5
        np.add(t2[:, 0], t2[:, 1], out=long_)
        long_ *= 0.5  # common torque
        lat *= gain
        np.subtract(long_, lat, out=t2[:, 0])
        np.add(long_, lat, out=t2[:, 1])
        return torques

    def clip_per_unit(self, torques: F64, tau_max: float) -> F64:
        """§5.4: scale each unit's torque pair so that neither exceeds tau_max (keeps the pair's ratio)."""
        t2 = torques.reshape(-1, 2)
        peak = self._u4
        np.maximum(np.abs(t2[:, 0], out=self._w4), np.abs(t2[:, 1], out=self._x4), out=peak)
        np.maximum(peak, tau_max, out=peak)
        np.divide(tau_max, peak, out=peak)
        t2 *= peak[:, None]
        return torques


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
