"""The handle side: the PD that holds the handle at its origin, and the car-driving map to a twist.

Thesis §5.2 (eq. 5.1, 5.2) and §5.3.1 (eq. 5.3, 5.4); docs/hallway-experiment.md (notation, §1, §11).

Axis conventions (the single place they are defined; every other module imports them)
----------------------------------------------------------------------------------
Handle: the Falcon device frame (libnifalcon), origin at the workspace centre, as seen by the
operator facing the device. It is right-handed: ``+x`` is the operator's right, ``+y`` is up,
``+z`` points towards the operator. Pushing the handle away from you ("forward") makes z
negative (thesis §5.3.1), and ``x > 0`` means "turn right" (thesis fig. 5.5). Forces use the
same axes: a positive ``F_z`` pushes the hand back towards the operator.

Platform twist ``[vx, vy, wz]``: the ropod robot frame (REP 103, as the ropod block and
docs/devices/ropod.md use it): x forward, y left, ``wz`` counter-clockwise positive, so a
left turn is ``wz > 0`` and the thesis's right turn for ``x > 0`` is ``wz < 0``.

Hence ``vx = k1·dz(−z)``, ``vy = 0``, ``wz = −k2·dz(x)``.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from annotated_types import Ge, Gt, Le
from numpy.typing import ArrayLike, NDArray

from hapticop.parameters import parameters

# Handle axes (indices into a position/force 3-vector, device frame).
HANDLE_X = 0  # + operator's right: steer right
HANDLE_Y = 1  # + up; not used for driving
HANDLE_Z = 2  # + towards the operator; pushing forward makes it negative

# Platform twist components (robot frame, REP 103).
TWIST_VX = 0  # m/s, + forward
TWIST_VY = 1  # m/s, + left (the car metaphor never commands it)
TWIST_WZ = 2  # rad/s, + counter-clockwise (left turn)

#: Forward speed grows with −z (thesis eq. 5.3: q1 = −z).
FORWARD_PER_HANDLE_Z = -1.0
#: Handle +x (operator's right) turns the robot right, i.e. clockwise: negative ``wz``.
YAW_PER_HANDLE_X = -1.0
#: Sign of a handle force along z that pushes the hand back (towards the operator): resists driving forward.
BACKWARD_FORCE_Z = +1.0
#: Sign of a handle force along x that pushes the hand to the operator's right: asks to steer right.
RIGHTWARD_FORCE_X = +1.0


@parameters
class CentringParams:
    """Gains of the centring PD that holds the handle at its origin (thesis §5.2, tuned on the real Falcon)."""

    kp_n_per_m: Annotated[float, Ge(0)] = 55.0
    """Spring to the origin, N/m."""
    kd_ns_per_m: Annotated[float, Ge(0)] = 0.2
    """Damper, N·s/m, on the handle velocity (see ``CentringPD`` for the eq. 5.2 ambiguity)."""
    force_limit_n: Annotated[float, Gt(0), Le(20.0)] = 10.0
    """Per-axis saturation of the whole force (centring plus environment): the Falcon renders about 10 N per axis."""
    period_s: Annotated[float, Gt(0)] = 0.001
    """Servo period, used only to difference positions when no velocity is supplied."""


class CentringPD:
    """Holds the handle at its origin so that displacement means "velocity command" (thesis eq. 5.2).

    ``F = sat(Kp·e + Kd·ė + F_env)`` with ``e = origin − p`` and ``ė = −ṗ``, saturated per axis
    after adding the environmental force (eq. 5.1: the operator feels the sum, and the device
    limit applies to the sum).

    Eq. 5.2 literally reads ``Kd·(e_k − e_(k−1))`` with Kd = 0.2, i.e. per sample. docs/hallway-experiment.md, the
    block and the stability analysis (docs/hallway-experiment.md §7.2) use Kd = 0.2 N·s/m on a velocity;
    we follow them (the per-sample reading would be 1000× less damping at 1 kHz).
    The velocity is the Falcon block's differentiated velocity when given, otherwise the backward
    difference of successive positions (the same signal, per docs/hallway-experiment.md §2).
    """

    def __init__(self, params: CentringParams = CentringParams(), origin: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        self.params = params
        ox, oy, oz = np.asarray(origin, dtype=np.float64).reshape(3).tolist()
        self._origin = (ox, oy, oz)
        self._prev = (0.0, 0.0, 0.0)
        self._primed = False

    def reset(self) -> None:
        """Forget the previous position (the next backward difference is zero)."""
        self._primed = False

    def compute(
        self,
        position: NDArray[np.float64],
        out: NDArray[np.float64],
        velocity: NDArray[np.float64] | None = None,
        env_force: NDArray[np.float64] | None = None,
    ) -> NDArray[np.float64]:
        """Write the saturated handle force for ``position`` (m, device frame) into ``out`` (N).

        Scalar maths on the three axes: for 3-vectors, Python floats beat numpy's per-call cost.
        """
        p = self.params
        px, py, pz = float(position[0]), float(position[1]), float(position[2])
        if velocity is not None:
            vx, vy, vz = float(velocity[0]), float(velocity[1]), float(velocity[2])
        elif self._primed:
            qx, qy, qz = self._prev
            rate = 1.0 / p.period_s
            vx, vy, vz = (px - qx) * rate, (py - qy) * rate, (pz - qz) * rate
        else:
            vx = vy = vz = 0.0
        if velocity is None:
            self._prev = (px, py, pz)
            self._primed = True
        # Kp·(origin − p) − Kd·ṗ (+ F_env), saturated per axis.
        kp, kd, limit = p.kp_n_per_m, p.kd_ns_per_m, p.force_limit_n
        ox, oy, oz = self._origin
        fx, fy, fz = (ox - px) * kp, (oy - py) * kp, (oz - pz) * kp
        if kd:
            fx, fy, fz = fx - vx * kd, fy - vy * kd, fz - vz * kd
        if env_force is not None:
            fx, fy, fz = fx + float(env_force[0]), fy + float(env_force[1]), fz + float(env_force[2])
        out[0] = _clip(fx, limit)
        out[1] = _clip(fy, limit)
        out[2] = _clip(fz, limit)
        return out


def saturate(force: NDArray[np.float64], limit_n: float) -> NDArray[np.float64]:
    """Clip each axis to ±limit in place: the Falcon's limit is per translational axis, not a norm."""
    np.minimum(force, limit_n, out=force)  # two ufuncs: np.clip's wrapper costs more than both
    return np.maximum(force, -limit_n, out=force)


def _clip(f: float, limit: float) -> float:
    """``saturate`` for one float (the PD's scalar path); NaN stays NaN, as numpy's minimum and maximum leave it."""
    f = limit if f > limit else f
    return -limit if f < -limit else f


def dead_zone(u: float, width: float, subtractive: bool = True) -> float:
    """Ignore small displacements so the robot does not creep (thesis §5.3.1).

    ``subtractive`` (default, docs/hallway-experiment.md's recommendation): ``sign(u)·max(|u| − width, 0)``, continuous.
    Otherwise the thesis's literal q: ``u`` if ``|u| > width`` else 0, which jumps by ``width`` at
    the edge (0.14 m/s of forward speed with k1 = 28 and a 5 mm zone).
    """
    a = abs(u)
    if a <= width:
        return 0.0
    if not subtractive:
        return u
    return math.copysign(a - width, u)


@parameters
class DrivingParams:
    """Car-driving metaphor gains (thesis §5.3.1: ratio of robot top speed to handle reach)."""

    k1_per_s: float = 28.0
    """Forward speed per forward handle displacement, (m/s)/m."""
    k2_rad_per_s_m: float = 10.0
    """Turn rate per sideways handle displacement, (rad/s)/m."""
    dead_zone_m: Annotated[float, Ge(0)] = 0.005
    """Dead zone on both x and z (thesis: z_dz = x_dz = 0.5 cm)."""
    subtractive_dead_zone: bool = True
    """True: continuous dead zone (notes). False: the thesis's literal, discontinuous one."""


def handle_to_twist(
    position: NDArray[np.float64], out: NDArray[np.float64], params: DrivingParams = DrivingParams()
) -> NDArray[np.float64]:
    """Platform twist ``[vx, vy, wz]`` for a handle position: position → velocity (rate) control.

    ``vx = k1·dz(−z)`` (eq. 5.3), ``wz = −k2·dz(x)`` (eq. 5.4 with x > 0 = turn right), ``vy = 0``.
    """
    z = float(position[HANDLE_Z])
    x = float(position[HANDLE_X])
    dz = params.dead_zone_m
    sub = params.subtractive_dead_zone
    out[TWIST_VX] = params.k1_per_s * dead_zone(FORWARD_PER_HANDLE_Z * z, dz, sub)
    out[TWIST_VY] = 0.0
    out[TWIST_WZ] = YAW_PER_HANDLE_X * params.k2_rad_per_s_m * dead_zone(x, dz, sub)
    return out


@parameters
class CorrectionFeelParams:
    """How a robot-side correction of the command (executed minus commanded twist, shared control S2) is
    felt on the handle: the hand is pushed the way the robot was made to go instead."""

    forward_n_per_mps: Annotated[float, Ge(0)] = 3.0
    """Force along the handle's forward axis per m/s of forward speed taken away (or added)."""
    lateral_n_per_mps: Annotated[float, Ge(0)] = 10.0
    """Force to the operator's side per m/s of sideways slide added: a slide to the right pushes right."""
    turn_n_per_rad_s: Annotated[float, Ge(0)] = 0.0
    """Force to the operator's side per rad/s of turn rate changed."""
    force_limit_n: Annotated[float, Gt(0)] = 2.0
    """Per-axis bound of this force."""
    smoothing_s: Annotated[float, Ge(0)] = 0.15
    """Time constant of the first-order low-pass the correction is felt through."""


class CorrectionFeel:
    """The feel of a twist correction ``[dvx, dvy, dwz]`` on the handle, smoothed to the hand's pace.

    Less forward speed pushes the hand back; a slide or turn to the robot's right pushes the hand to the
    operator's right, which is where the car map would have to be pushed to ask for it. The correction
    changes with each scan (15 Hz); felt raw, its steps would be the jolts the calm stop removed."""

    def __init__(self, params: CorrectionFeelParams, period_s: float) -> None:
        self.params = params
        self.period_s = period_s
        self.felt = [0.0, 0.0, 0.0]

    def reset(self) -> None:
        self.felt[:] = [0.0, 0.0, 0.0]

    def add(self, correction: NDArray[np.float64], force: NDArray[np.float64]) -> NDArray[np.float64]:
        """Add this cycle's force to ``force`` (device frame)."""
        p, felt = self.params, self.felt
        a = self.period_s / (p.smoothing_s + self.period_s)
        for i in range(3):
            felt[i] += a * (float(correction[i]) - felt[i])
        limit = p.force_limit_n
        fz = -BACKWARD_FORCE_Z * p.forward_n_per_mps * felt[TWIST_VX]
        fx = -RIGHTWARD_FORCE_X * (p.lateral_n_per_mps * felt[TWIST_VY] + p.turn_n_per_rad_s * felt[TWIST_WZ])
        force[HANDLE_Z] += limit if fz > limit else -limit if fz < -limit else fz
        force[HANDLE_X] += limit if fx > limit else -limit if fx < -limit else fx
        return force
