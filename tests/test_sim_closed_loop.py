"""The pieces together: operator on a handle, world, recorder, metrics (§4's F0 baseline and a stopping cue).

The robot here is a test-only kinematic stand-in (the pose integrates the commanded twist); the real plant is
hapticop/devices/ropod/plant.py.
"""

import math

import numpy as np

from hapticop.sim.hallway_task import Hallway
from hapticop.sim.metrics import compute_metrics
from hapticop.sim.operator import BlindOperator, OperatorProfile
from hapticop.sim.recording import TrajectoryRecorder

KP, KD, M_DEVICE, K1, K2, DZ = 55.0, 0.2, 0.1, 28.0, 10.0, 0.005


def dead_zone(u):
    return math.copysign(max(abs(u) - DZ, 0.0), u)


def run(cue, seconds=30.0, dt=1e-3):
    g = Hallway.named("H1")
    engine = g.engine()
    end_wall_x = 10.0  # H1's
    profile = OperatorProfile.nominal()
    op = BlindOperator(profile)
    rec = TrajectoryRecorder(int(seconds / dt) + 1, meta={"hallway": g.name})
    pose = np.array(g.start, float)
    p, v, hand, fe = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    c, hit = math.inf, False
    for k in range(int(seconds / dt)):
        t = k * dt
        gap = end_wall_x - (pose[0] + 0.5 * g.footprint.length_m) - g.dist2_m
        fe[2] = cue(gap) if p[2] < 0 else 0.0
        op.step(t, fe, p, hand, velocity=v)
        force = hand + fe - KP * p - KD * v
        force[1] = 0.0
        v += force / (M_DEVICE + op.mass_kg) * dt
        p += v * dt
        cmd = (K1 * dead_zone(-p[2]), -K2 * dead_zone(p[0]))  # handle +x turns right (clockwise)
        pose += (cmd[0] * math.cos(pose[2]) * dt, cmd[0] * math.sin(pose[2]) * dt, cmd[1] * dt)
        if k % 5 == 0:  # every 5 ms (under 3 mm of travel) keeps the test quick
            engine.place_robot(pose)
            c = engine.clearance()
            hit = c <= 0.0
        rec.append(t, pose, robot_velocity=cmd, cmd=cmd, handle_position=p, handle_velocity=v,
                   force_env=fe, force_hand=hand, clearance=c)
        if hit:
            break
    return compute_metrics(rec, g, v_cruise_mps=profile.cruise_speed())


def test_without_a_force_the_blind_operator_crashes():
    m = run(lambda gap: 0.0)
    assert m.crash and m.ended_by == "crash"
    assert m.t_end_s > 8.65 / 0.56  # drove the whole hallway at cruise speed


def test_a_strong_enough_cue_makes_the_operator_stop_before_the_wall():
    # 6 N over the last metre before the stop line, held at 6 N past it.
    m = run(lambda gap: 6.0 * min(max(1.0 - gap / 1.0, 0.0), 1.0))
    assert not m.crash and m.ended_by == "stopped"
    assert -0.5 < m.e_stop_m < 1.0 and m.force_peak_n <= 6.0
