"""S1, the robot-side speed governor: limit the commanded twist so the robot stops before obstacles.

docs/hallway-experiment.md §1 item 2 and §10: no handle force can stop an operator who keeps pushing,
so safety needs a robot-side limit on the robot's own undelayed scan:

    v_exec = min(v_cmd, √(2·a_b·g⁺))        g = front-of-footprint gap to obstacles − dist2

and, near the side walls, ω clipped so the predicted clearance stays ≥ dist3. The governor only
ever scales a command towards zero (it never reverses, never adds speed, never steers by itself),
so the operator keeps authority whenever the command is safe.

Turning bound: moving at v for T_p while turning at ω shifts the body sideways by about
v·ω·T_p²/2 towards the side it turns to, so with c_S the side clearance after translating by
v·T_p (``BeamGeometry.side_clearances``), c_L − v·ω·T_p²/2 ≥ dist3 gives
ω ≤ 2(c_L − dist3)/(v·T_p²) and symmetrically ω ≥ −2(c_R − dist3)/(v·T_p²).
Sideways speed (the ropod is holonomic) gets the braking law on the current side clearance.

The scan changes at 15 Hz and the command at 1 kHz, so the work is split as in the force models:
``govern_scan`` once per scan (load, side points, stop gap), ``govern_cycle`` every cycle;
``govern_twist`` does both for a caller that does not track scan arrival.

Limits: the LIDAR's 270° cannot see behind, so reversing is not limited; turning on the spot
(v ≤ 0) is not limited (the swept corners are not modelled).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from annotated_types import Ge, Gt
from numpy.typing import NDArray

from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.handle import TWIST_VX, TWIST_VY, TWIST_WZ
from hapticop.parameters import parameters


@parameters
class GovernorParams:
    """S1, the robot-side speed governor (docs/hallway-experiment.md §2, §10): the robot stops before
    obstacles however hard it is pushed."""

    brake_decel_mps2: Annotated[float, Gt(0)] = 0.5
    """a_b: planned deceleration; tune to the robot's real limits (§10)."""
    stop_distance_m: Annotated[float, Ge(0)] = 0.50
    """dist2: the robot stops with this much front clearance."""
    bumper_m: Annotated[float, Ge(0)] = 0.10
    """dist3: hard side clearance the turning bound keeps."""
    lead_time_s: Annotated[float, Gt(0)] = 1.5
    """T_p: prediction horizon for the side clearance."""
    corridor_margin_m: Annotated[float, Ge(0)] = 0.10
    """Stop-corridor half-width beyond the body (same choice as M1's m_c)."""
    window_rear_m: Annotated[float, Ge(0)] = 0.5
    """Side window reaches this far behind the body."""
    window_ahead_m: Annotated[float, Ge(0)] = 1.5
    """Side window reaches this far ahead of the body."""
    robust_k: Annotated[int, Ge(1)] = 3
    """k-th smallest clearance: ignores up to k − 1 spurious beams."""


@parameters
class BlindPolicy:
    """What the robot may do while the scan is stale (older than its stream's max_age), when nothing
    can be felt nor governed."""

    policy: Literal["stop", "slow"] = "stop"
    """'stop' commands no motion; 'slow' limits the robot to speed_mps and turn_rad_s."""
    speed_mps: Annotated[float, Ge(0)] = 0.1
    """Speed limit while blind (policy 'slow')."""
    turn_rad_s: Annotated[float, Ge(0)] = 0.2
    """Turn-rate limit while blind (policy 'slow')."""


def govern_scan(ranges: NDArray[np.floating], beams: BeamGeometry, params: GovernorParams = GovernorParams()) -> float:
    """S1's work on a new scan (15 Hz): load it into ``beams``, select the side points, and return
    the stop gap ``g`` (front-of-footprint gap to the corridor's obstacles − dist2) for ``govern_cycle``."""
    beams.load(ranges)
    return _govern_loaded(beams, params)


def govern_field(field: NDArray[np.float64], beams: BeamGeometry, params: GovernorParams = GovernorParams()) -> float:
    """``govern_scan`` for a scan rendered beside the loop (``hapticop.haptics.scan_field``): its
    points are taken as they are."""
    beams.load_points(field)
    return _govern_loaded(beams, params)


def _govern_loaded(beams: BeamGeometry, params: GovernorParams) -> float:
    beams.select_sides(params.window_rear_m, params.window_ahead_m)
    return stop_gap(beams, params)


def stop_gap(beams: BeamGeometry, params: GovernorParams = GovernorParams()) -> float:
    """The stop gap ``g`` of the scan already in ``beams`` (for beams another user loaded and selected
    with this footprint and side window, such as the braking field's)."""
    return beams.corridor_gap(params.corridor_margin_m, params.robust_k) - params.stop_distance_m


def govern_cycle(
    twist_cmd: NDArray[np.float64],
    beams: BeamGeometry,
    gap_m: float,
    out: NDArray[np.float64],
    params: GovernorParams = GovernorParams(),
) -> NDArray[np.float64]:
    """Write the executed twist ``[vx, vy, wz]`` for a commanded one into ``out`` (1 kHz); allocation-free.

    ``beams`` and ``gap_m`` are what ``govern_scan`` made of the latest scan.
    Each output component has the command's sign and at most its magnitude.
    """
    p = params
    a2 = 2.0 * p.brake_decel_mps2
    vx = float(twist_cmd[TWIST_VX])
    vy = float(twist_cmd[TWIST_VY])
    wz = float(twist_cmd[TWIST_WZ])

    if vx > 0.0:
        vx = min(vx, math.sqrt(a2 * gap_m) if gap_m > 0.0 else 0.0)

    if vy != 0.0:
        c_left, c_right = beams.side_clearances(0.0, 0.0, p.robust_k)
        room = (c_left if vy > 0.0 else c_right) - p.bumper_m
        v_side = math.sqrt(a2 * room) if room > 0.0 else 0.0
        vy = math.copysign(min(abs(vy), v_side), vy)

    if vx > 0.0 and wz != 0.0:
        t = p.lead_time_s
        c_left, c_right = beams.side_clearances(vx * t, vy * t, p.robust_k)
        k = 2.0 / (vx * t * t)
        if wz > 0.0:  # turning left, towards the left side
            wz = min(wz, max(0.0, k * (c_left - p.bumper_m)))
        else:
            wz = max(wz, min(0.0, -k * (c_right - p.bumper_m)))

    out[TWIST_VX] = vx
    out[TWIST_VY] = vy
    out[TWIST_WZ] = wz
    return out


def govern_twist(
    twist_cmd: NDArray[np.float64],
    ranges: NDArray[np.floating],
    beams: BeamGeometry,
    out: NDArray[np.float64],
    params: GovernorParams = GovernorParams(),
) -> NDArray[np.float64]:
    """``govern_scan`` then ``govern_cycle``: one full evaluation, for a caller that does not track scan arrival.

    ``beams`` is a ``BeamGeometry`` for the scan's angles (robot frame) and footprint, built once.
    """
    return govern_cycle(twist_cmd, beams, govern_scan(ranges, beams, params), out, params)


def limit_blind(twist: NDArray[np.float64], speed_mps: float, turn_rad_s: float) -> NDArray[np.float64]:
    """Without a fresh scan: scale the translation down to `speed_mps` and clip the turn rate, in place.

    Direction is kept (the operator still steers); `speed_mps = turn_rad_s = 0` is a full stop.
    """
    vx, vy = float(twist[TWIST_VX]), float(twist[TWIST_VY])
    speed = math.hypot(vx, vy)
    if speed > speed_mps:
        scale = speed_mps / speed
        twist[TWIST_VX] = vx * scale
        twist[TWIST_VY] = vy * scale
    twist[TWIST_WZ] = min(max(float(twist[TWIST_WZ]), -turn_rad_s), turn_rad_s)
    return twist


def limit_blind_by(twist: NDArray[np.float64], blind: BlindPolicy) -> NDArray[np.float64]:
    """``limit_blind`` as the policy says: a full stop, or its slow limits."""
    if blind.policy == "stop":
        return limit_blind(twist, 0.0, 0.0)
    return limit_blind(twist, blind.speed_mps, blind.turn_rad_s)
