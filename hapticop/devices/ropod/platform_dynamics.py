"""The ropod platform's equations of motion (Level 1) and their RK4 step, on plain floats.

This is the simulated robot's innermost loop: four derivative evaluations a millisecond. It is
kept apart from the plant (drives, images, noise) so that it can be compiled: when the package
is built with Cython, `platform_dynamics.pxd` types its attributes and locals as C doubles and
this same file becomes an extension module. Interpreted or compiled, every operation is the
same IEEE double operation in the same order, so a run's results are bit for bit the same
(tests/test_compiled_kernels.py compares the two). `math.cos` and `math.sin` stay Python's in
both: they call the same libm, and raise on an infinite angle where C's would return NaN.
"""

from __future__ import annotations

import math

from hapticop.devices.ropod.kinematics import inverse_sym3

__all__ = ["PlatformDynamics"]


class PlatformDynamics:
    """dy = f(y) of the rigid platform on its caster units, for torques held over a step.

    The state y is pose (3), twist (3), pivot angles (units), wheel angles (2 per unit), model
    convention. The plant writes `torque_sum` ((t1 + t2)/r per unit), `torque_diff` (k (t2 - t1)/r)
    and `external` (force x, y and torque on the platform, its frame) before each step.
    """

    def __init__(self, units: int, unit_rows, inv_r: float, k: float, inv_s: float, ic_s2: float,
                 mass_kg: float, yaw_inertia_kgm2: float, pivot_damping_nms: float,
                 linear_damping_ns_per_m: float, yaw_damping_nms: float):
        self.units = units
        self.rows = [float(v) for row in unit_rows for v in row]  # ua, ub, qa, qb per unit
        self.inv_r, self.k, self.inv_s, self.ic = inv_r, k, inv_s, ic_s2
        self.friction = pivot_damping_nms * inv_s
        self.pivot_damping, self.mass = pivot_damping_nms, mass_kg
        self.linear_damping, self.yaw_damping = linear_damping_ns_per_m, yaw_damping_nms
        self.d0, self.d1, self.d2 = float(mass_kg), float(mass_kg), float(yaw_inertia_kgm2)
        self.e0, self.e1, self.e2 = 1.0 / self.d0, 1.0 / self.d1, 1.0 / self.d2
        self.torque_sum = [0.0] * units
        self.torque_diff = [0.0] * units
        self.external = [0.0, 0.0, 0.0]
        size = 6 + 3 * units
        self.yt, self.k1, self.k2, self.k3, self.k4 = ([0.0] * size for _ in range(5))

    def derivative(self, y: list, dy: list) -> None:
        """dy = f(y) (docs/devices/ropod.md §8).

        Per unit, with U_i and Q_i of its pivot angle: the yaw rate Omega_i = Q_i v / s, the pivot
        rate Omega_i - wz, the wheel speeds (U_i v -+ k Q_i v) / r, and its share of the wrench
        G^T tau = sum (t1 + t2)/r U_i + k (t2 - t1)/r Q_i. The casters' steering inertia and their
        bearings' friction both act through Q_i: rhs += sum Q_i delta_dot_i (I_c/s^2 U_i v - b_p/s),
        plus b_p sum delta_dot_i on the yaw; the mass matrix is M + I_c/s^2 sum Q_i^T Q_i.
        """
        units, rows, torque_sum, torque_diff = self.units, self.rows, self.torque_sum, self.torque_diff
        theta, vx, vy, wz = y[2], y[3], y[4], y[5]
        c, s = math.cos(theta), math.sin(theta)
        dy[0] = c * vx - s * vy
        dy[1] = s * vx + c * vy
        dy[2] = wz
        inv_s, inv_r, k, ic, friction = self.inv_s, self.inv_r, self.k, self.ic, self.friction
        fx = fy = mz = 0.0  # wrench
        sdd = w0 = w1 = w2 = 0.0  # sum of pivot rates, sum Q_i delta_dot_i (I_c/s^2 u_i - b_p/s)
        m00 = m01 = m02 = m11 = m12 = m22 = 0.0  # sum Q_i^T Q_i
        for i in range(units):
            ua, ub, qa, qb = rows[4 * i], rows[4 * i + 1], rows[4 * i + 2], rows[4 * i + 3]
            a, b = torque_sum[i], torque_diff[i]
            ci, si = math.cos(y[6 + i]), math.sin(y[6 + i])
            u3, q3 = ci * ua + si * ub, ci * qa + si * qb
            q = ci * vy - si * vx + q3 * wz
            u = ci * vx + si * vy + u3 * wz
            dd = q * inv_s - wz
            dy[6 + i] = dd
            j = 6 + units + 2 * i
            dy[j] = (u - k * q) * inv_r
            dy[j + 1] = (u + k * q) * inv_r
            fx += a * ci - b * si
            fy += a * si + b * ci
            mz += a * u3 + b * q3
            sdd += dd
            w = dd * (ic * u - friction)
            w0 -= si * w
            w1 += ci * w
            w2 += q3 * w
            m00 += si * si
            m01 -= si * ci
            m02 -= si * q3
            m11 += ci * ci
            m12 += ci * q3
            m22 += q3 * q3
        m = self.mass
        external = self.external
        ex, ey, ez = external[0], external[1], external[2]
        r0 = fx + (m * wz * vy - self.linear_damping * vx) + w0 + ex
        r1 = fy + (-m * wz * vx - self.linear_damping * vy) + w1 + ey
        r2 = mz - self.yaw_damping * wz + self.pivot_damping * sdd + w2 + ez
        if ic:
            _, i00, i01, i02, i11, i12, i22 = inverse_sym3(m00 * ic + self.d0, m01 * ic, m02 * ic,
                                                          m11 * ic + self.d1, m12 * ic, m22 * ic + self.d2)
            dy[3] = i00 * r0 + i01 * r1 + i02 * r2
            dy[4] = i01 * r0 + i11 * r1 + i12 * r2
            dy[5] = i02 * r0 + i12 * r1 + i22 * r2
        else:
            dy[3] = r0 * self.e0
            dy[4] = r1 * self.e1
            dy[5] = r2 * self.e2

    def rk4(self, y: list, h: float) -> None:
        """One classical Runge-Kutta step of y in place; pose and wheel angles feed nothing back,
        so the stage states only carry heading, twist and pivot angles."""
        yt, k1, k2, k3, k4 = self.yt, self.k1, self.k2, self.k3, self.k4
        coupled_end = 6 + self.units
        hh = 0.5 * h
        self.derivative(y, k1)
        for j in range(2, coupled_end):
            yt[j] = k1[j] * hh + y[j]
        self.derivative(yt, k2)
        for j in range(2, coupled_end):
            yt[j] = k2[j] * hh + y[j]
        self.derivative(yt, k3)
        for j in range(2, coupled_end):
            yt[j] = k3[j] * h + y[j]
        self.derivative(yt, k4)
        h6 = h / 6.0
        for j in range(len(y)):
            y[j] += (k1[j] + (k2[j] + k3[j]) * 2.0 + k4[j]) * h6
