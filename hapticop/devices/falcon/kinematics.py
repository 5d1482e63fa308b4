"""Novint Falcon kinematics: encoder counts, handle position, forces and motor commands.

The Falcon is Stamper's 3-DOF translational parallel mechanism with libnifalcon's extra
offsets (docs/devices/falcon-kinematics.md); its numbers are in `mechanism`, one leg's maths
in `legs`. Inverse kinematics is analytic; forward kinematics is Newton-Raphson on it,
warm-started from the previous answer, solved to 1e-12 rad / 1e-10 m so the position does
not lag the encoders the way libnifalcon's 0.01 rad, half-step solver does (§6). Forces
map to thigh torques through the true Jacobian transpose, tau = J^T F; libnifalcon's
`getForces` uses a symmetrised J with a wrong z column (§5, §8): over the reference poses
its torque vector is off by up to 94 % (norm), so the force felt is not the force asked for.

The per-call maths is scalar `math` on Python floats, three legs unrolled: at 3-vectors and
3x3 matrices numpy's per-call overhead, not arithmetic, would be the cost. Array outputs are
written in place into caller-provided arrays: nothing is created per 1 kHz cycle that stays.
One `FalconKinematics` per thread.

This module and `legs` are compiled kernels: when the package is built with Cython,
`kinematics.pxd` and `legs.pxd` type their attributes and locals as C doubles and the legs'
IK and Jacobian rows become C calls. Interpreted or compiled, every operation is the same
IEEE double operation in the same order (tests/test_compiled_kernels.py compares the two);
`math`'s functions stay Python's, imported by name: a global look-up per call, not an attribute one.
"""

from __future__ import annotations

from math import inf, isfinite, sqrt

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hapticop.devices.falcon.legs import LegMaths, Pose
from hapticop.devices.falcon.mechanism import Drive, Geometry

__all__ = ["FalconKinematics"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def _three(values: ArrayLike) -> tuple[float, float, float]:
    """The three numbers of a 3-vector; arrays through `tolist`, far cheaper than iterating them."""
    a, b, c = values.tolist() if isinstance(values, np.ndarray) else values  # type: ignore[misc]
    return a, b, c


def _put(out: np.ndarray, a: float, b: float, c: float) -> None:
    """Write three values into a caller's (3,) array: three item stores beat one sequence copy."""
    out[0] = a
    out[1] = b
    out[2] = c


class FalconKinematics:
    """Counts <-> angles <-> position, Jacobian, and force -> motor command for one Falcon.

    All per-cycle methods take `out` arrays (float64 or int64, shape (3,)) and return a
    bool instead of raising: False means unreachable, singular or not converged, and the
    `out` array is then left as it was (motor commands are zeroed, the safe value).

    `forward` remembers its last solution as the next starting point and the leg angles
    there, so `forces_to_motor(None, ...)` right after it needs no second IK. `pose` and
    `pose_force` are the same maths for callers that keep their state in floats (the
    simulator): no arrays at all.
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
        # IK evaluations per `forward`: bounds the cost of a failure (unreachable counts).
        # libnifalcon instead silently keeps the old position.
        self.max_evaluations, self.warm_evaluations = int(max_evaluations), int(warm_evaluations)
        self._budget = 0
        self.max_condition = float(max_condition)
        x, y, z = np.array(initial_guess_m, dtype=np.float64).reshape(3).tolist()
        self._guess0: tuple[float, float, float] = (x, y, z)
        self._leg1, self._leg2, self._leg3 = (LegMaths(g, phi) for phi in g.leg_angles_deg)
        self._rad_per_count = dr.rad_per_count
        self._zero_rad = dr.zero_count_rad
        self._motor_per_nm = float(dr.motor_per_nm)
        self._motor_cap = min(float(dr.motor_limit), dr.torque_limit_nm * abs(dr.motor_per_nm))
        # The last Jacobian: M^T row-major (rows x, y, z; columns legs), Q = det * M^-1
        # row-major (the cofactors of M^T), and det M^T.
        self._Mt: tuple[float, ...] = (0.0,) * 9
        self._Q: tuple[float, ...] = (0.0,) * 9
        self._det = 0.0
        self._meas = (0.0, 0.0, 0.0)  # measured thigh angles `forward` solves for
        self._last = self._guess0  # warm start
        self._cur: Pose | None = None  # IK at _last while _have_last
        self._have_last = False
        #: Iterations and final |residual| (rad, Euclidean) of the last `forward` call.
        self.iterations = 0
        self.residual = inf

    # ------------------------------------------------------------------ encoders
    def angles_from_counts(self, counts: ArrayLike, out: F64) -> F64:
        """Thigh angles theta1 (rad) of encoder counts (§7): 35 deg + 6.359e-4 rad per count."""
        a, b, c = _three(counts)
        r, z = self._rad_per_count, self._zero_rad
        _put(out, a * r + z, b * r + z, c * r + z)
        return out

    def count(self, theta1: float) -> int:
        """Nearest encoder count of one thigh angle (ties to even), not wrapped."""
        return round((theta1 - self._zero_rad) / self._rad_per_count)

    def counts_from_angles(self, theta1: ArrayLike, out: I64) -> I64:
        """Nearest encoder counts of thigh angles (the simulator's encoder), not wrapped.

        ValueError/OverflowError for NaN or infinite angles: they have no count.
        """
        a, b, c = _three(theta1)
        _put(out, self.count(a), self.count(b), self.count(c))
        return out

    # ------------------------------------------------------------------ inverse
    def pose(self, x: float, y: float, z: float) -> Pose | None:
        """The three legs' IK at a handle position (m); None if unreachable."""
        leg1 = self._leg1.ik(x, y, z)
        if leg1 is None:
            return None
        leg2 = self._leg2.ik(x, y, z)
        if leg2 is None:
            return None
        leg3 = self._leg3.ik(x, y, z)
        if leg3 is None:
            return None
        return (leg1, leg2, leg3)

    def inverse(self, position: ArrayLike, out_theta1: F64,
                out_theta2: F64 | None = None, out_theta3: F64 | None = None) -> bool:
        """Thigh angles (rad) for a handle position (m); False, `out` untouched, if unreachable.

        libnifalcon returns NaN and "success" there (§4); we say so instead.
        """
        pose = self.pose(*_three(position))
        if pose is None:
            return False
        l1, l2, l3 = pose
        _put(out_theta1, l1[0], l2[0], l3[0])
        if out_theta2 is not None:
            _put(out_theta2, l1[1], l2[1], l3[1])
        if out_theta3 is not None:
            _put(out_theta3, l1[2], l2[2], l3[2])
        return True

    # ------------------------------------------------------------------ Jacobian
    def _jac(self, pose: Pose) -> bool:
        """M = d theta1 / d p (§5) and Q = det * M^-1 at `pose`; False if near-singular."""
        r1 = self._leg1.row(pose[0])
        r2 = self._leg2.row(pose[1])
        r3 = self._leg3.row(pose[2])
        if r1 is None or r2 is None or r3 is None:
            return False
        # M^T: column k is leg k's row of M.
        a00, a10, a20 = r1
        a01, a11, a21 = r2
        a02, a12, a22 = r3
        # Q[i] = M^T[i+1] x M^T[i+2]: the cofactors of M^T, so that J = M^-1 = Q / det.
        q00, q01, q02 = a11 * a22 - a12 * a21, a12 * a20 - a10 * a22, a10 * a21 - a11 * a20
        q10, q11, q12 = a21 * a02 - a22 * a01, a22 * a00 - a20 * a02, a20 * a01 - a21 * a00
        q20, q21, q22 = a01 * a12 - a02 * a11, a02 * a10 - a00 * a12, a00 * a11 - a01 * a10
        det = a00 * q00 + a01 * q01 + a02 * q02
        # Frobenius condition number ||M|| ||M^-1|| guards the inversion, as docs/devices/falcon-kinematics.md ask.
        norm_m = (a00 * a00 + a01 * a01 + a02 * a02 + a10 * a10 + a11 * a11 + a12 * a12
                  + a20 * a20 + a21 * a21 + a22 * a22)
        norm_q = (q00 * q00 + q01 * q01 + q02 * q02 + q10 * q10 + q11 * q11 + q12 * q12
                  + q20 * q20 + q21 * q21 + q22 * q22)
        if not (det != 0.0 and sqrt(norm_m * norm_q) <= self.max_condition * abs(det)):
            return False
        self._Mt = (a00, a01, a02, a10, a11, a12, a20, a21, a22)
        self._Q = (q00, q01, q02, q10, q11, q12, q20, q21, q22)
        self._det = det
        return True

    def jacobian(self, position: ArrayLike, out_J: F64, out_M: F64 | None = None) -> bool:
        """J = d p / d theta1 (m/rad, 3x3) at a position, and optionally M = J^-1 (rad/m)."""
        pose = self.pose(*_three(position))
        if pose is None or not self._jac(pose):
            return False
        np.divide(np.reshape(self._Q, (3, 3)), self._det, out=out_J)  # off the cycle path
        if out_M is not None:
            np.copyto(out_M, np.reshape(self._Mt, (3, 3)).T)
        return True

    # ------------------------------------------------------------------ forward
    def forward(self, encoders: ArrayLike, out_position: F64) -> bool:
        """Handle position (m) from encoder counts; False if unreachable or not converged."""
        a, b, c = _three(encoders)
        r, z = self._rad_per_count, self._zero_rad
        self._meas = (a * r + z, b * r + z, c * r + z)
        return self._solve(out_position)

    def forward_angles(self, theta1: ArrayLike, out_position: F64) -> bool:
        """Handle position (m) from thigh angles (rad); see `forward`."""
        self._meas = _three(theta1)
        return self._solve(out_position)

    def reset(self) -> None:
        """Forget the warm start (e.g. after homing made the counts jump)."""
        self._last = self._guess0
        self._have_last = False

    def _solve(self, out_position: F64) -> bool:
        """Newton from the last solution; if that fails within `warm_evaluations` IK calls (a
        jump across the workspace), once more from the initial guess with what is left of
        `max_evaluations`. The warm start stays at the last good solution."""
        cur = self._cur if self._have_last else self.pose(*self._last)
        self._have_last = False  # the solution moves away from _last from here on
        self._budget = self.warm_evaluations
        solution = None if cur is None else self._newton(self._last, cur)
        if solution is None:
            iterations = self.iterations if cur is not None else 0
            self._budget = self.max_evaluations - (self.warm_evaluations - self._budget) - 1
            cur = self.pose(*self._guess0)
            solution = None if cur is None else self._newton(self._guess0, cur)
            self.iterations += iterations
        if solution is None:
            return False
        self._last, self._cur = solution
        self._have_last = True
        _put(out_position, *self._last)
        return True

    def _newton(self, p: tuple[float, float, float], cur: Pose
                ) -> tuple[tuple[float, float, float], Pose] | None:
        """Newton-Raphson p <- p + J (theta_meas - theta1(p)) from p, whose IK is `cur`.

        Full steps, halved while the trial is unreachable or the residual does not fall.
        Stops when |residual| <= tol_rad or after a step <= tol_m (quadratic convergence
        puts the root far closer than that); at most max_iterations. At 1 kHz a warm start
        needs 1-3 iterations. Returns the root and its IK, or None if not converged.
        """
        tol_rad, tol_m = self.tol_rad, self.tol_m
        m0, m1, m2 = self._meas
        x, y, z = p
        e0, e1, e2 = m0 - cur[0][0], m1 - cur[1][0], m2 - cur[2][0]
        rn = sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        converged = rn <= tol_rad
        it = 0
        while not converged and it < self.max_iterations and self._budget > 0:
            it += 1
            if not self._jac(cur):
                break
            q00, q01, q02, q10, q11, q12, q20, q21, q22 = self._Q
            inv_det = 1.0 / self._det
            s0 = (q00 * e0 + q01 * e1 + q02 * e2) * inv_det  # J e
            s1 = (q10 * e0 + q11 * e1 + q12 * e2) * inv_det
            s2 = (q20 * e0 + q21 * e1 + q22 * e2) * inv_det
            norm = sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            lam, trial, rt = 1.0, None, inf
            for _ in range(min(self.max_halvings, self._budget)):
                self._budget -= 1
                tx, ty, tz = s0 * lam + x, s1 * lam + y, s2 * lam + z
                trial = self.pose(tx, ty, tz)
                if trial is not None:
                    f0, f1, f2 = m0 - trial[0][0], m1 - trial[1][0], m2 - trial[2][0]
                    rt = sqrt(f0 * f0 + f1 * f1 + f2 * f2)
                    if rt < rn or rt <= tol_rad:
                        break
                    trial = None
                lam *= 0.5
            if trial is None:
                converged = norm <= tol_m  # rounding floor, within tol_m of the root
                break
            x, y, z, cur = tx, ty, tz, trial
            e0, e1, e2, rn = f0, f1, f2, rt
            converged = rn <= tol_rad or lam * norm <= tol_m
        self.iterations, self.residual = it, rn
        return ((x, y, z), cur) if converged else None

    # ------------------------------------------------------------------ forces
    def _pose(self, position: ArrayLike | None) -> bool:
        """IK and Jacobian at `position`, or at the last `forward` solution for None."""
        if position is None:
            if not self._have_last:  # the last forward failed: its last good pose
                cur = self.pose(*self._last)
                if cur is None:
                    return False
                self._cur, self._have_last = cur, True
            return self._jac(self._cur)  # type: ignore[arg-type]
        pose = self.pose(*_three(position))
        return pose is not None and self._jac(pose)

    def _torques(self, f0: float, f1: float, f2: float) -> tuple[float, float, float]:
        """tau = J^T F = (Q^T F) / det at the last Jacobian."""
        q00, q01, q02, q10, q11, q12, q20, q21, q22 = self._Q
        inv_det = 1.0 / self._det
        return ((f0 * q00 + f1 * q10 + f2 * q20) * inv_det, (f0 * q01 + f1 * q11 + f2 * q21) * inv_det,
                (f0 * q02 + f1 * q12 + f2 * q22) * inv_det)

    def forces_to_torques(self, position: ArrayLike | None, force: ArrayLike, out_tau: F64) -> bool:
        """Thigh torques tau = J^T F (N m) for a handle force F (N) at a position (m).

        `position=None` means the pose of the last successful `forward` (no extra IK).
        """
        if not self._pose(position):
            return False
        _put(out_tau, *self._torques(*_three(force)))
        return True

    def pose_force(self, pose: Pose, tau1: float, tau2: float, tau3: float) -> tuple[float, float, float] | None:
        """Handle force F = J^-T tau = M^T tau (N) that thigh torques produce at `pose`; None if singular."""
        if not self._jac(pose):
            return None
        a00, a01, a02, a10, a11, a12, a20, a21, a22 = self._Mt
        return (a00 * tau1 + a01 * tau2 + a02 * tau3, a10 * tau1 + a11 * tau2 + a12 * tau3,
                a20 * tau1 + a21 * tau2 + a22 * tau3)

    def torques_to_force(self, position: ArrayLike | None, tau: ArrayLike, out_force: F64) -> bool:
        """Handle force F = J^-T tau = M^T tau (N) that thigh torques produce (the simulator's motors)."""
        if not self._pose(position):
            return False
        a00, a01, a02, a10, a11, a12, a20, a21, a22 = self._Mt
        t0, t1, t2 = _three(tau)
        _put(out_force, a00 * t0 + a01 * t1 + a02 * t2, a10 * t0 + a11 * t1 + a12 * t2,
             a20 * t0 + a21 * t1 + a22 * t2)
        return True

    def torques_to_motor(self, tau: ArrayLike, out_motor: I64) -> bool:
        """Motor commands from thigh torques: trunc(-10000 tau), saturated without turning F.

        When any command would exceed the limit all three are scaled down together (as
        libnifalcon does for its 30 N m torque clamp), so the rendered force keeps its
        direction; per-axis clipping would bend it. Non-finite torques give zeros, False.
        """
        t0, t1, t2 = _three(tau)
        return self._motor(t0, t1, t2, out_motor)

    def _motor(self, t0: float, t1: float, t2: float, out_motor: I64) -> bool:
        """`torques_to_motor` on floats."""
        k = self._motor_per_nm
        m0, m1, m2 = t0 * k, t1 * k, t2 * k
        if not (isfinite(m0) and isfinite(m1) and isfinite(m2)):
            out_motor.fill(0)
            return False
        peak, cap = max(abs(m0), abs(m1), abs(m2)), self._motor_cap
        if peak > cap:
            scale = cap / peak
            m0, m1, m2 = m0 * scale, m1 * scale, m2 * scale
        _put(out_motor, int(m0), int(m1), int(m2))  # int() truncates toward zero
        return True

    def forces_to_motor(self, position: ArrayLike | None, force: ArrayLike, out_motor: I64) -> bool:
        """Motor commands for a handle force at a position (None: last `forward` pose).

        False (and zero commands) if the pose is unreachable/singular or the force not finite.
        """
        if not self._pose(position):
            out_motor.fill(0)
            return False
        f0, f1, f2 = _three(force)
        t0, t1, t2 = self._torques(f0, f1, f2)
        return self._motor(t0, t1, t2, out_motor)
