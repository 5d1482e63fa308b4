"""Where the robot will be when the command sent now reaches it, from the commands already sent.

Model-mediated rendering (docs/teleop.md; docs/hallway-experiment.md §7.4): the operator's host
renders the force from the latest scan it has, which shows the robot where it was when the scan was
taken, a delay ago. The robot had then executed the commands sent up to a forward delay before the
scan; when the command sent now arrives it will have executed every command sent until now. Both
ends of that stretch are known to the operator's host, so the robot's motion between the scan and
the command's arrival is the dead reckoning of the commands sent over it:

    travel = P(now) ⊖ P(t_scan − τ_fwd)

with P the pose obtained by integrating the commanded twists (each held until the next, integrated
exactly as an arc) and ⊖ the pose of the first in the frame of the second. It is exact while the
robot executes the commands as sent; the governor or the wheels' dynamics make the robot lag, and
the prediction then puts it nearer to the obstacles than it is (the safe side).
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from annotated_types import Ge, Gt
from numpy.typing import NDArray

from hapticop.parameters import parameters


@parameters
class PredictionParams:
    """How the commands sent are remembered and how far ahead they take the robot."""

    forward_delay_s: Annotated[float, Ge(0)] = 0.0
    """τ_fwd: a command's way to the robot, when no measured round trip is at hand (then half of it)."""
    history_s: Annotated[float, Gt(0)] = 3.0
    """How far back the commands are kept; a scan older than this plus τ_fwd is predicted from the oldest."""
    period_s: Annotated[float, Gt(0)] = 0.001
    """The commands' period, which sizes the memory."""


def arc(vx: float, vy: float, wz: float, dt: float) -> tuple[float, float, float]:
    """The displacement (dx, dy, dθ), in the starting frame, of a body holding the twist for ``dt``."""
    dth = wz * dt
    if abs(dth) < 1e-9:
        s, c = dt * (1.0 - dth * dth / 6.0), dt * (-dth / 2.0)  # sin(wt)/w and (cos(wt) − 1)/w to second order
    else:
        s, c = math.sin(dth) / wz, (math.cos(dth) - 1.0) / wz
    return s * vx + c * vy, -c * vx + s * vy, dth


class CommandOdometry:
    """The pose the commands sent would give the robot, remembered over ``history_s``; allocation-free."""

    def __init__(self, params: PredictionParams = PredictionParams()) -> None:
        self.params = params
        n = int(math.ceil(params.history_s / params.period_s)) + 2
        # entry i: from time t[i] the robot holds twist[i], starting from pose[i] (world frame x, y, θ)
        self._t = np.full(n, -math.inf)
        self._pose = np.zeros((n, 3))
        self._twist = np.zeros((n, 3))
        self._n = n
        self._last = -1  # index of the newest entry; -1: no command yet
        self._count = 0

    def command(self, t_s: float, twist: NDArray[np.float64]) -> None:
        """The command ``twist`` [vx, vy, wz] was sent at ``t_s`` (times not decreasing)."""
        if self._last >= 0:
            x, y, th = self.pose_at(t_s)
        else:
            x = y = th = 0.0
        i = (self._last + 1) % self._n
        self._t[i] = t_s
        self._pose[i, 0], self._pose[i, 1], self._pose[i, 2] = x, y, th
        self._twist[i, 0], self._twist[i, 1], self._twist[i, 2] = float(twist[0]), float(twist[1]), float(twist[2])
        self._last = i
        self._count += 1

    def pose_at(self, t_s: float) -> tuple[float, float, float]:
        """The commanded pose at ``t_s`` (world frame of the odometry); before the memory, its oldest pose."""
        if self._last < 0:
            return 0.0, 0.0, 0.0
        i = self._find(t_s)
        x0, y0, th0 = float(self._pose[i, 0]), float(self._pose[i, 1]), float(self._pose[i, 2])
        dt = t_s - float(self._t[i])
        if dt <= 0.0:
            return x0, y0, th0
        dx, dy, dth = arc(float(self._twist[i, 0]), float(self._twist[i, 1]), float(self._twist[i, 2]), dt)
        c, s = math.cos(th0), math.sin(th0)
        return x0 + c * dx - s * dy, y0 + s * dx + c * dy, th0 + dth

    def travel(self, since_s: float, until_s: float, out: NDArray[np.float64]) -> NDArray[np.float64]:
        """The motion (dx, dy, dθ) from the pose at ``since_s`` to the pose at ``until_s``, in the frame of
        the first, into ``out``."""
        x0, y0, th0 = self.pose_at(since_s)
        x1, y1, th1 = self.pose_at(until_s)
        c, s = math.cos(th0), math.sin(th0)
        dx, dy = x1 - x0, y1 - y0
        out[0], out[1], out[2] = c * dx + s * dy, -s * dx + c * dy, th1 - th0
        return out

    def _find(self, t_s: float) -> int:
        """The newest entry that started at or before ``t_s`` (the oldest kept, if none): a binary search
        over the ring, newest first."""
        kept = min(self._count, self._n)
        newest, n, times = self._last, self._n, self._t
        if float(times[newest]) <= t_s:
            return newest
        lo, hi = 1, kept - 1  # look k entries back; entry k back started at or before t_s?
        oldest = (newest - hi) % n
        if float(times[oldest]) > t_s:
            return oldest
        while lo < hi:  # invariant: entry hi back is at or before t_s, entry lo - 1 back is after
            mid = (lo + hi) // 2
            if float(times[(newest - mid) % n]) <= t_s:
                hi = mid
            else:
                lo = mid + 1
        return (newest - lo) % n
