"""One leg of the Falcon's parallel mechanism: its analytic inverse kinematics and Jacobian row.

Per leg (docs/devices/falcon-kinematics.md §2-§5): an actuated thigh angle theta1, the
parallelogram direction theta2 and the parallelogram tilt theta3. `FalconKinematics`
(`kinematics`) runs three of these per call; the maths is scalar `math` on Python floats,
since at this size numpy's per-call overhead, not arithmetic, would be the cost. Compiled
with `kinematics` (`legs.pxd`), same bits either way.
"""

from __future__ import annotations

from math import acos, atan2, cos, radians, sin, sqrt

from hapticop.devices.falcon.mechanism import Geometry

__all__ = ["Leg", "Pose", "LegMaths"]

#: One leg's IK state: (theta1, theta2, theta3, sin theta3, cos theta3, K, n0, n1), where
#: K = d + e + b sin theta3 and (n0, n1) = K (sin theta2, cos theta2) is the platform joint
#: seen from the elbow.
Leg = tuple[float, float, float, float, float, float, float, float]
#: The three legs' IK states at one handle position (legs 1, 2, 3).
Pose = tuple[Leg, Leg, Leg]


class LegMaths:
    """One leg's constants (§2) and its per-call IK and Jacobian row, on floats."""

    __slots__ = ("cphi", "sphi", "sphi_b", "cphi_b", "u0", "v0", "a", "a2", "two_a", "b", "de")

    def __init__(self, g: Geometry, phi_deg: float) -> None:
        phi = radians(phi_deg)
        self.cphi, self.sphi = cos(phi), sin(phi)
        # Leg frame: w = z, X = u + c = cphi x + sphi y + (c - r), cos theta3 = (v + f) / b.
        self.sphi_b, self.cphi_b = self.sphi / g.b, self.cphi / g.b
        self.u0, self.v0 = g.c - g.r, (g.f - g.s) / g.b
        self.a, self.a2, self.two_a, self.b, self.de = g.a, g.a * g.a, 2.0 * g.a, g.b, g.d + g.e

    def ik(self, x: float, y: float, z: float) -> Leg | None:
        """Analytic IK of §4; None if unreachable (an arccos argument leaves [-1, 1])."""
        X = self.cphi * x + self.sphi * y + self.u0
        c3 = self.cphi_b * y - self.sphi_b * x + self.v0
        if not -1.0 <= c3 <= 1.0:  # also False for NaN
            return None
        t3 = acos(c3)
        s3 = sin(t3)
        K = s3 * self.b + self.de
        rho2 = X * X + z * z
        if not rho2 > 0.0:
            return None
        # cosine of the angle between thigh and platform joint
        cosine = (rho2 - K * K + self.a2) / (sqrt(rho2) * self.two_a)
        if not -1.0 <= cosine <= 1.0:
            return None
        t1 = atan2(z, X) - acos(cosine)  # libnifalcon's elbow branch
        # theta2 = direction of (X - a cos t1, w - a sin t1). It equals libnifalcon's
        # acos((X - a cos t1) / K) wherever w - a sin t1 >= 0 (every sampled point).
        n0 = z - self.a * sin(t1)
        n1 = X - self.a * cos(t1)
        return (t1, atan2(n0, n1), t3, s3, c3, K, n0, n1)

    def row(self, leg: Leg) -> tuple[float, float, float] | None:
        """Row of M = d theta1 / d p for this leg; None if D = -a sin t3 sin(t1 - t2) ~ 0.

        (cos phi cos t2 sin t3 - sin phi cos t3, sin phi cos t2 sin t3 + cos phi cos t3,
        sin t2 sin t3) / D. libnifalcon's z entry is sin^2 t2 / D (its issue #66); this is
        the correct one.
        """
        t1, t2, _, s3, c3, K, n0, n1 = leg
        D = -self.a * (sin(t1 - t2) * s3)
        if not abs(D) > 1e-12:  # theta3 at 0 or pi, or thigh along link
            return None
        c2s3 = n1 / K * s3
        return ((self.cphi * c2s3 - self.sphi * c3) / D, (self.sphi * c2s3 + self.cphi * c3) / D,
                n0 / K * s3 / D)
