"""Novint Falcon kinematics: encoder counts, handle position, forces and motor commands.

The Falcon is Stamper's 3-DOF translational parallel mechanism with libnifalcon's extra
offsets (falcon-kinematics.md). Per leg: an actuated thigh angle theta1, the parallelogram
direction theta2 and the parallelogram tilt theta3. Inverse kinematics is analytic; forward
kinematics is Newton-Raphson on it, warm-started from the previous answer, solved to
1e-12 rad / 1e-10 m so the position does not lag the encoders the way libnifalcon's
0.01 rad, half-step solver does (§6). Forces map to thigh torques through the true
Jacobian transpose, tau = J^T F; libnifalcon's `getForces` uses a symmetrised J with a
wrong z column (§5, §8): over the reference poses its torque vector is off by up to 94 %
(norm), so the force felt is not the force asked for.

Everything a 1 kHz cycle calls writes into caller-provided arrays and preallocated work
arrays: no numpy array is created per call. One `FalconKinematics` per thread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Geometry", "Drive", "FalconKinematics", "WORKSPACE_CENTRE_M", "WORKSPACE_BOX_M",
]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Centre of the sampled reachable box (§9: x, y in +-45 mm, z in 80..170 mm). The device
#: frame has no agreed origin (libnifalcon 0.150, ros_falcon_interface 0.125 ...): blocks
#: choose theirs and subtract it after FK.
WORKSPACE_CENTRE_M: tuple[float, float, float] = (0.0, 0.0, 0.125)
#: (low, high) corners of that box, metres. Not every corner is reachable.
WORKSPACE_BOX_M: tuple[tuple[float, float, float], tuple[float, float, float]] = (
    (-0.045, -0.045, 0.080), (0.045, 0.045, 0.170))


@dataclass(frozen=True)
class Geometry:
    """Mechanism dimensions in metres, libnifalcon's values and signs (falcon-kinematics.md §1).

    The thesis (appendix B) lists r = 36.60, s = 23.09, f = 25.00 mm unsigned plus an unused
    g; following the notes we default to libnifalcon's r = 40.00, s = -23.09, f = -25.00 mm,
    the values all reference data was produced with. With r = 36.6 mm the same counts land
    up to ~4 mm elsewhere, so keep the geometry a parameter. Field names match the Falcon
    block's `FalconGeometry` params, so `Geometry(**params.model_dump())` works.
    """

    a: float = 0.060  # thigh length
    b: float = 0.1025  # parallelogram link length
    c: float = 0.01443  # platform radius
    d: float = 0.01125  # parallelogram to platform joint offset
    e: float = 0.01125  # thigh to parallelogram offset
    f: float = -0.025  # platform-side offset along the joint axis v
    r: float = 0.0400  # base radius
    s: float = -0.02309  # base-side offset along v
    # Leg directions in the x-y plane, legs 1 (top), 2 (right), 3 (left) seen from the front.
    leg_angles_deg: tuple[float, float, float] = (105.0, -15.0, -135.0)


@dataclass(frozen=True)
class Drive:
    """Encoder and motor conversions of one leg (falcon-kinematics.md §7, §8).

    An encoder of 320 slots read in quadrature gives 1280 counts per motor turn; a 14.25 mm
    capstan drives a 110 mm arm sector, so one count is 6.359e-4 rad of thigh; count 0
    (once homed) is taken as 35 deg. Angles use exact degree-to-radian conversion, not
    libnifalcon's rounded 0.0174532925 (relative difference 1e-9, i.e. < 1e-10 m).

    `motor_per_nm` is libnifalcon's empirical torque-to-command factor and sign
    (motor = trunc(-10000 tau)), a starting point, not a calibration: Novint's own driver
    was seen using a different scale. `motor_limit` is the +-4095 the notes recommend
    (protocol §4.1) until hardware says otherwise; `torque_limit_nm` is libnifalcon's 30 N m.
    """

    counts_per_turn: int = 320 * 4
    capstan_diameter_m: float = 0.01425
    sector_diameter_m: float = 0.110
    zero_count_deg: float = 35.0
    motor_per_nm: float = -10000.0
    motor_limit: int = 4095
    torque_limit_nm: float = 30.0

    @property
    def rad_per_count(self) -> float:
        return 2.0 * math.pi / self.counts_per_turn * self.capstan_diameter_m / self.sector_diameter_m

    @property
    def zero_count_rad(self) -> float:
        return math.radians(self.zero_count_deg)


class _Legs:
    """IK results of the three legs at one position, laid out for few numpy calls."""

    def __init__(self) -> None:
        self.q = np.zeros(9)  # [w (3), X = u + c (3), cos theta3 (3)]
        self.wX = self.q[0:6].reshape(2, 3)
        self.w, self.X, self.c3 = self.q[0:3], self.q[3:6], self.q[6:9]
        self.t1, self.t2, self.t3 = np.zeros(3), np.zeros(3), np.zeros(3)
        self.s3, self.K = np.zeros(3), np.zeros(3)  # sin theta3, K = d + e + b sin theta3
        self.n = np.zeros((2, 3))  # K (sin theta2, cos theta2): platform joint seen from the elbow
        self.n0, self.n1 = self.n[0], self.n[1]


def _in_unit(values: list[float]) -> bool:
    """All three within [-1, 1] (False for NaN): the arccos domain, checked before calling it."""
    a, b, c = values
    return -1.0 <= a <= 1.0 and -1.0 <= b <= 1.0 and -1.0 <= c <= 1.0


class FalconKinematics:
    """Counts <-> angles <-> position, Jacobian, and force -> motor command for one Falcon.

    All per-cycle methods take `out` arrays (float64 or int64, shape (3,)) and return a
    bool instead of raising: False means unreachable, singular or not converged, and the
    `out` array is then left as it was (motor commands are zeroed, the safe value).

    `forward` remembers its last solution as the next starting point and the leg angles
    there, so `forces_to_motor(None, ...)` right after it needs no second IK. The work is
    laid out so a Newton iteration is ~45 numpy calls on 3-vectors: at this size numpy's
    per-call overhead, not arithmetic, is the cost.
    """

    def __init__(self, geometry: Geometry | None = None, drive: Drive | None = None, *,
                 tol_rad: float = 1e-12, tol_m: float = 1e-10, max_iterations: int = 20,
                 max_halvings: int = 8, max_evaluations: int = 40, warm_evaluations: int = 12,
                 max_condition: float = 1e6,
                 initial_guess_m: ArrayLike = (0.0, 0.0, 0.12)) -> None:
        self.geometry = g = geometry if geometry is not None else Geometry()
        self.drive = dr = drive if drive is not None else Drive()
        self.tol_rad, self.tol_m = float(tol_rad), float(tol_m)
        self.max_iterations, self.max_halvings = int(max_iterations), int(max_halvings)
        # IK evaluations per `forward`: bounds the cost of a failure (unreachable counts:
        # ~0.8 ms on our machine, against ~80 us for a warm 1 kHz call). libnifalcon instead
        # silently keeps the old position.
        self.max_evaluations, self.warm_evaluations = int(max_evaluations), int(warm_evaluations)
        self._budget = 0
        self.max_condition = float(max_condition)
        self._guess0 = np.array(initial_guess_m, dtype=np.float64).reshape(3)
        phi = np.radians(np.asarray(g.leg_angles_deg, dtype=np.float64))
        cphi, sphi = np.cos(phi), np.sin(phi)
        # Leg frames (§2) as one product: [w, X = u + c, cos theta3 = (v + f) / b] = R p + o.
        self._R = np.zeros((9, 3))
        self._R[0:3, 2] = 1.0
        self._R[3:6, 0], self._R[3:6, 1] = cphi, sphi
        self._R[6:9, 0], self._R[6:9, 1] = -sphi / g.b, cphi / g.b
        self._o = np.concatenate([np.zeros(3), np.full(3, g.c - g.r), np.full(3, (g.f - g.s) / g.b)])
        self._phi_a = np.stack([cphi, sphi])  # x, y rows of M^T: phi_a c2 s3 + phi_b c3
        self._phi_b = np.stack([-sphi, cphi])
        self._rad_per_count = dr.rad_per_count
        self._zero_rad = dr.zero_count_rad
        z = lambda: np.zeros(3)  # noqa: E731
        self._cur, self._trial = _Legs(), _Legs()  # swapped by reference during Newton
        self._p, self._t, self._rho = z(), z(), z()
        self._sq = np.zeros((2, 3))
        self._sq0, self._sq1 = self._sq[0], self._sq[1]
        # Jacobian work. G rows: M^T (x, y, z rows; leg columns), then cos theta2 sin theta3.
        # M = d theta1 / d p; Q[i] = M^T[i+1] x M^T[i+2], so J = M^-1 = Q / det.
        self._G = np.zeros((4, 3))
        self._Mt = self._G[0:3]
        self._Mt_flat = self._Mt.reshape(9)
        self._Mt01, self._Mt0 = self._G[0:2], self._G[0]
        self._S = self._G[2:4]  # [sin t2 sin t3, cos t2 sin t3]
        self._c2s3 = self._G[3]
        self._T23 = np.zeros((2, 3))
        self._D = z()
        self._Q = np.zeros((3, 3))
        self._Q_flat, self._Q0 = self._Q.reshape(9), self._Q[0]
        i, k = np.divmod(np.arange(9), 3)
        row = lambda di, dk: 3 * ((i + di) % 3) + (k + dk) % 3  # noqa: E731
        self._cross_idx = np.stack([row(1, 1), row(1, 2), row(2, 2), row(2, 1)]).astype(np.intp)
        self._cross_T = np.zeros((4, 9))
        self._cross_a, self._cross_b = self._cross_T[0:2], self._cross_T[2:4]
        self._cross_P = np.zeros((2, 9))
        self._cross_P0, self._cross_P1 = self._cross_P[0], self._cross_P[1]
        self._det = 0.0
        # Newton and force work.
        self._meas, self._res, self._step, self._ptrial = z(), z(), z(), z()
        self._vec, self._tau, self._motor_f = z(), z(), z()
        self._last = self._guess0.copy()  # warm start
        self._have_last = False  # _cur holds IK at _last
        #: Iterations and final |residual| (rad, Euclidean) of the last `forward` call.
        self.iterations = 0
        self.residual = math.inf

    # ------------------------------------------------------------------ encoders
    def angles_from_counts(self, counts: ArrayLike, out: F64) -> F64:
        """Thigh angles theta1 (rad) of encoder counts (§7): 35 deg + 6.359e-4 rad per count."""
        np.multiply(counts, self._rad_per_count, out=out)
        np.add(out, self._zero_rad, out=out)
        return out

    def counts_from_angles(self, theta1: ArrayLike, out: I64) -> I64:
        """Nearest encoder counts of thigh angles (the simulator's encoder), not wrapped."""
        t = self._t
        np.subtract(theta1, self._zero_rad, out=t)
        np.divide(t, self._rad_per_count, out=t)
        np.rint(t, out=t)
        np.copyto(out, t, casting="unsafe")
        return out

    # ------------------------------------------------------------------ inverse
    def _ik(self, p: F64, L: _Legs) -> bool:
        """Analytic IK of §4 into `L`; False if unreachable (an arccos argument leaves [-1, 1])."""
        g = self.geometry
        t, rho, sq = self._t, self._rho, self._sq
        self._R.dot(p, out=L.q)
        np.add(L.q, self._o, out=L.q)
        if not _in_unit(L.c3.tolist()):
            return False
        np.arccos(L.c3, out=L.t3)
        np.sin(L.t3, out=L.s3)
        np.multiply(L.s3, g.b, out=L.K)
        np.add(L.K, g.d + g.e, out=L.K)
        np.multiply(L.wX, L.wX, out=sq)
        np.add(self._sq0, self._sq1, out=rho)  # rho^2 = X^2 + w^2
        if not min(rho.tolist()) > 0.0:
            return False
        np.multiply(L.K, L.K, out=t)
        np.subtract(rho, t, out=t)
        np.add(t, g.a * g.a, out=t)  # a^2 + rho^2 - K^2
        np.sqrt(rho, out=rho)
        np.multiply(rho, 2.0 * g.a, out=rho)
        np.divide(t, rho, out=t)  # cosine of the angle between thigh and platform joint
        if not _in_unit(t.tolist()):
            return False
        np.arccos(t, out=t)
        np.arctan2(L.w, L.X, out=L.t1)
        np.subtract(L.t1, t, out=L.t1)  # theta1 = alpha - acos(.): libnifalcon's elbow branch
        # theta2 = direction of (X - a cos t1, w - a sin t1). It equals libnifalcon's
        # acos((X - a cos t1) / K) wherever w - a sin t1 >= 0 (every sampled point).
        np.sin(L.t1, out=L.n0)
        np.cos(L.t1, out=L.n1)
        np.multiply(L.n, -g.a, out=L.n)
        np.add(L.n, L.wX, out=L.n)
        np.arctan2(L.n0, L.n1, out=L.t2)
        return True

    def inverse(self, position: ArrayLike, out_theta1: F64,
                out_theta2: F64 | None = None, out_theta3: F64 | None = None) -> bool:
        """Thigh angles (rad) for a handle position (m); False, `out` untouched, if unreachable.

        libnifalcon returns NaN and "success" there (§4); we say so instead.
        """
        np.copyto(self._p, position)
        if not self._ik(self._p, self._trial):
            return False
        np.copyto(out_theta1, self._trial.t1)
        if out_theta2 is not None:
            np.copyto(out_theta2, self._trial.t2)
        if out_theta3 is not None:
            np.copyto(out_theta3, self._trial.t3)
        return True

    def counts_from_position(self, position: ArrayLike, out: I64) -> bool:
        """Encoder counts (absolute, homed) for a handle position; False if unreachable."""
        np.copyto(self._p, position)
        if not self._ik(self._p, self._trial):
            return False
        self.counts_from_angles(self._trial.t1, out)
        return True

    # ------------------------------------------------------------------ Jacobian
    def _jac(self, L: _Legs) -> bool:
        """M = d theta1 / d p (§5) and Q = det * M^-1 at IK state `L`; False if near-singular.

        Row i of M: (cos phi cos t2 sin t3 - sin phi cos t3, sin phi cos t2 sin t3 +
        cos phi cos t3, sin t2 sin t3) / D with D = -a sin t3 sin(t1 - t2). libnifalcon's
        z entry is sin^2 t2 / D (its issue #66); this is the correct one.
        """
        D = self._D
        np.subtract(L.t1, L.t2, out=D)
        np.sin(D, out=D)
        np.multiply(D, L.s3, out=D)
        np.multiply(D, -self.geometry.a, out=D)
        d0, d1, d2 = D.tolist()
        if not min(abs(d0), abs(d1), abs(d2)) > 1e-12:  # theta3 at 0 or pi, or thigh along link
            return False
        np.divide(L.n, L.K, out=self._S)  # sin t2, cos t2
        np.multiply(self._S, L.s3, out=self._S)
        np.multiply(self._phi_a, self._c2s3, out=self._Mt01)
        np.multiply(self._phi_b, L.c3, out=self._T23)
        np.add(self._Mt01, self._T23, out=self._Mt01)
        np.divide(self._Mt, D, out=self._Mt)  # M^T: columns are legs, each over its D
        # Q[i] = M^T[i+1] x M^T[i+2] for all i at once through one gather.
        self._Mt_flat.take(self._cross_idx, out=self._cross_T, mode="wrap")
        np.multiply(self._cross_a, self._cross_b, out=self._cross_P)
        np.subtract(self._cross_P0, self._cross_P1, out=self._Q_flat)
        det = float(self._Mt0.dot(self._Q0))
        # Frobenius condition number ||M|| ||M^-1|| guards the inversion, as the notes ask.
        norms = float(self._Mt_flat.dot(self._Mt_flat)) * float(self._Q_flat.dot(self._Q_flat))
        if not (det != 0.0 and math.sqrt(norms) <= self.max_condition * abs(det)):
            return False
        self._det = det
        return True

    def jacobian(self, position: ArrayLike, out_J: F64, out_M: F64 | None = None) -> bool:
        """J = d p / d theta1 (m/rad, 3x3) at a position, and optionally M = J^-1 (rad/m)."""
        np.copyto(self._p, position)
        if not (self._ik(self._p, self._trial) and self._jac(self._trial)):
            return False
        np.divide(self._Q, self._det, out=out_J)
        if out_M is not None:
            np.copyto(out_M, self._Mt.T)
        return True

    # ------------------------------------------------------------------ forward
    def forward(self, encoders: ArrayLike, out_position: F64) -> bool:
        """Handle position (m) from encoder counts; False if unreachable or not converged."""
        self.angles_from_counts(encoders, self._meas)
        return self._solve(out_position)

    def forward_angles(self, theta1: ArrayLike, out_position: F64) -> bool:
        """Handle position (m) from thigh angles (rad); see `forward`."""
        np.copyto(self._meas, theta1)
        return self._solve(out_position)

    def reset(self) -> None:
        """Forget the warm start (e.g. after homing made the counts jump)."""
        np.copyto(self._last, self._guess0)
        self._have_last = False

    def _residual(self, L: _Legs) -> float:
        np.subtract(self._meas, L.t1, out=self._res)
        return math.sqrt(float(self._res.dot(self._res)))

    def _solve(self, out_position: F64) -> bool:
        """Newton from the last solution; if that fails within `warm_evaluations` IK calls (a
        jump across the workspace), once more from the initial guess with what is left of
        `max_evaluations`. The warm start stays at the last good solution."""
        p = self._p
        np.copyto(p, self._last)
        warm = self._have_last or self._ik(p, self._cur)
        self._have_last = False  # p moves away from _last from here on
        self._budget = self.warm_evaluations
        converged = warm and self._newton(p)
        if not converged:
            iterations = self.iterations if warm else 0
            self._budget = self.max_evaluations - (self.warm_evaluations - self._budget) - 1
            np.copyto(p, self._guess0)
            converged = self._ik(p, self._cur) and self._newton(p)
            self.iterations += iterations
        if not converged:
            return False
        np.copyto(self._last, p)
        self._have_last = True
        np.copyto(out_position, p)
        return True

    def _newton(self, p: F64) -> bool:
        """Newton-Raphson p <- p + J (theta_meas - theta1(p)) from p, whose IK is in _cur.

        Full steps, halved while the trial is unreachable or the residual does not fall.
        Stops when |residual| <= tol_rad or after a step <= tol_m (quadratic convergence
        puts the root far closer than that); at most max_iterations. At 1 kHz a warm start
        needs 1-3 iterations.
        """
        trial, step = self._ptrial, self._step
        rn = self._residual(self._cur)
        converged = rn <= self.tol_rad
        it = 0
        while not converged and it < self.max_iterations and self._budget > 0:
            it += 1
            if not self._jac(self._cur):
                break
            self._Q.dot(self._res, out=step)  # det * J e
            np.multiply(step, 1.0 / self._det, out=step)
            norm = math.sqrt(float(step.dot(step)))
            lam, accepted, rt = 1.0, False, math.inf
            for _ in range(min(self.max_halvings, self._budget)):
                self._budget -= 1
                if lam == 1.0:
                    np.add(p, step, out=trial)
                else:
                    np.multiply(step, lam, out=trial)
                    np.add(trial, p, out=trial)
                if self._ik(trial, self._trial):
                    rt = self._residual(self._trial)
                    if rt < rn or rt <= self.tol_rad:
                        accepted = True
                        break
                lam *= 0.5
            if not accepted:
                self._residual(self._cur)
                converged = norm <= self.tol_m  # rounding floor, within tol_m of the root
                break
            np.copyto(p, trial)
            self._cur, self._trial = self._trial, self._cur
            rn = rt
            converged = rn <= self.tol_rad or lam * norm <= self.tol_m
        self.iterations, self.residual = it, rn
        return converged

    # ------------------------------------------------------------------ forces
    def _pose(self, position: ArrayLike | None) -> bool:
        """IK and Jacobian at `position`, or at the last `forward` solution for None."""
        if position is None:
            if not self._have_last:  # the last forward failed: its last good pose
                if not self._ik(self._last, self._cur):
                    return False
                self._have_last = True
            return self._jac(self._cur)
        np.copyto(self._p, position)
        return self._ik(self._p, self._trial) and self._jac(self._trial)

    def forces_to_torques(self, position: ArrayLike | None, force: ArrayLike, out_tau: F64) -> bool:
        """Thigh torques tau = J^T F (N m) for a handle force F (N) at a position (m).

        `position=None` means the pose of the last successful `forward` (no extra IK).
        """
        if not self._pose(position):
            return False
        np.copyto(self._vec, force)
        self._vec.dot(self._Q, out=out_tau)  # (Q^T F) = det * J^T F
        np.multiply(out_tau, 1.0 / self._det, out=out_tau)
        return True

    def torques_to_force(self, position: ArrayLike | None, tau: ArrayLike, out_force: F64) -> bool:
        """Handle force F = J^-T tau = M^T tau (N) that thigh torques produce (the simulator's motors)."""
        if not self._pose(position):
            return False
        np.copyto(self._vec, tau)
        self._Mt.dot(self._vec, out=out_force)
        return True

    def torques_to_motor(self, tau: ArrayLike, out_motor: I64) -> bool:
        """Motor commands from thigh torques: trunc(-10000 tau), saturated without turning F.

        When any command would exceed the limit all three are scaled down together (as
        libnifalcon does for its 30 N m torque clamp), so the rendered force keeps its
        direction; per-axis clipping would bend it. Non-finite torques give zeros, False.
        """
        dr, m = self.drive, self._motor_f
        np.multiply(tau, dr.motor_per_nm, out=m)
        a, b, c = m.tolist()
        peak = max(abs(a), abs(b), abs(c))
        if not math.isfinite(peak):
            out_motor.fill(0)
            return False
        limit = min(float(dr.motor_limit), dr.torque_limit_nm * abs(dr.motor_per_nm))
        if peak > limit:
            np.multiply(m, limit / peak, out=m)
        np.trunc(m, out=m)
        np.copyto(out_motor, m, casting="unsafe")
        return True

    def forces_to_motor(self, position: ArrayLike | None, force: ArrayLike, out_motor: I64) -> bool:
        """Motor commands for a handle force at a position (None: last `forward` pose).

        False (and zero commands) if the pose is unreachable/singular or the force not finite.
        """
        if not self.forces_to_torques(position, force, self._tau):
            out_motor.fill(0)
            return False
        return self.torques_to_motor(self._tau, out_motor)
