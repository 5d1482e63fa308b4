"""The numeric kernels (modules with a `.pxd` beside them, compiled by setup.py): compiled, and
bit for bit what their Python source computes.

Under CI the kernels must have been compiled (a green CI means the compiled code is what ran);
elsewhere an uncompiled install skips the comparison, since there is only one version to compare.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import math
import os
import random
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

import hapticop
from hapticop.devices.falcon.mechanism import WORKSPACE_BOX_M, Drive, Geometry
from hapticop.devices.ropod.controller_params import THESIS_PLATFORM_THETA, THESIS_PLATFORM_XY, THESIS_WHEEL
from hapticop.devices.ropod.plant import PlantParams, RopodPlant

PACKAGE = Path(hapticop.__file__).parent
KERNELS = sorted(".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts) for p in PACKAGE.rglob("*.pxd"))


def _compiled(name: str):
    module = importlib.import_module(name)
    if not module.__file__.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)):
        if os.environ.get("CI"):
            pytest.fail(f"{name} runs uncompiled under CI: setup.py did not build it (is a C compiler there?)")
        pytest.skip(f"{name} is not compiled in this install: nothing to compare its source with")
    return module


def _interpreted(name: str):
    """The kernel's `.py` source as a module of its own, run by the interpreter."""
    path = PACKAGE.parent.joinpath(*name.split(".")).with_suffix(".py")
    spec = importlib.util.spec_from_loader(f"{name}_interpreted",
                                           importlib.machinery.SourceFileLoader(f"{name}_interpreted", str(path)))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


def _bits(values) -> bytes:
    """The exact doubles, every NaN as one (C and Python may set a NaN's sign bit differently)."""
    return struct.pack(f"{len(values)}d", *(math.nan if math.isnan(v) else v for v in values))


def test_the_kernels_are_found_and_each_is_compiled_from_its_current_source():
    assert "hapticop.devices.ropod.platform_dynamics" in KERNELS
    for name in KERNELS:
        built = Path(_compiled(name).__file__)
        source = built.parent / name.rsplit(".", 1)[1]
        for typed in (source.with_suffix(".py"), source.with_suffix(".pxd")):
            assert built.stat().st_mtime >= typed.stat().st_mtime, (
                f"{built.name} is older than {typed.name}: the run would use the old code; pip install -e . again")


def test_no_kernel_defines_a_parameter_set_or_model():
    """A compiled class has no source: pydantic would find no field docstrings, and the reference and the
    schema would lose their descriptions. Parameter sets live in plain modules."""
    for name in KERNELS:
        module = importlib.import_module(name)
        for value in vars(module).values():
            if isinstance(value, type) and value.__module__ == name:
                assert not hasattr(value, "__pydantic_config__") and not hasattr(value, "model_fields"), (
                    f"{name}.{value.__name__} is a parameter set or model in a compiled kernel")


@pytest.mark.parametrize("level", ["level 1 (caster inertia, pivot friction)", "level 0"])
def test_the_platform_dynamics_compiled_computes_the_same_bits_as_its_source(level):
    name = "hapticop.devices.ropod.platform_dynamics"
    compiled, source = _compiled(name), _interpreted(name)
    assert compiled.PlatformDynamics is not source.PlatformDynamics
    params = PlantParams(pivot_damping_nms=0.03) if level.startswith("level 1") else PlantParams(
        unit_yaw_inertia_kgm2=0.0)
    body = RopodPlant(params)._body  # built by the plant, as a run builds it
    assert type(body) is compiled.PlatformDynamics
    rows = [tuple(body.rows[4 * i:4 * i + 4]) for i in range(body.units)]
    twin = source.PlatformDynamics(body.units, rows, body.inv_r, body.k, body.inv_s, body.ic, body.mass,
                                   params.yaw_inertia_kgm2, body.pivot_damping, body.linear_damping,
                                   body.yaw_damping)
    rng = random.Random(7)
    size = 6 + 3 * body.units
    failures = 0
    for trial in range(300):
        y = [rng.uniform(-4.0, 4.0) for _ in range(size)]
        if trial % 50 == 0:  # extremes: huge, tiny, zero, infinite, NaN
            y = [rng.choice([0.0, 1e-300, -1e300, 1e12, math.pi, math.inf, math.nan]) for _ in range(size)]
        torque_sum = [rng.uniform(-60, 60) if trial % 7 else 0.0 for _ in range(body.units)]
        torque_diff = [rng.uniform(-5, 5) for _ in range(body.units)]
        external = [rng.uniform(-200, 200), rng.uniform(-200, 200), rng.uniform(-30, 30)]
        for side in (body, twin):
            side.torque_sum[:], side.torque_diff[:], side.external[:] = torque_sum, torque_diff, external
        dy_c, dy_s = [0.0] * size, [0.0] * size
        assert _outcome(body.derivative, list(y), dy_c) == _outcome(twin.derivative, list(y), dy_s)
        assert _bits(dy_c) == _bits(dy_s), f"derivative differs at trial {trial}"
        y_c, y_s = list(y), list(y)
        h = rng.choice([1e-3, 2.5e-4, 0.02])
        assert _outcome(body.rk4, y_c, h) == _outcome(twin.rk4, y_s, h), f"trial {trial}"
        assert _bits(y_c) == _bits(y_s), f"RK4 step differs at trial {trial}"
        failures += _outcome(twin.rk4, list(y), h) is not None
    assert failures, "the extremes never reached an infinite angle: the raising path went untested"


def _outcome(step, *args) -> tuple[type, str] | None:
    """None, or the error a step raised (an infinite angle: math's ValueError in both)."""
    try:
        step(*args)
    except ArithmeticError as error:  # what C arithmetic might do instead: never expected
        raise AssertionError(f"{step} raised {error!r}") from error
    except ValueError as error:
        return type(error), str(error)
    return None


def test_the_ropod_controller_bank_compiled_computes_the_same_bits_as_its_source():
    name = "hapticop.devices.ropod.linear_bank"
    compiled, source = _compiled(name), _interpreted(name)
    channels = [THESIS_PLATFORM_XY, THESIS_PLATFORM_XY, THESIS_PLATFORM_THETA, *[THESIS_WHEEL] * 8]
    bank = compiled.ControllerBank(channels, 1e-3)
    twin = source.ControllerBank(channels, 1e-3)
    assert type(bank) is not type(twin)
    rng = random.Random(5)
    out, out_twin = [0.0] * 11, [0.0] * 11
    clamped = 0
    for step in range(5000):
        scale = rng.choice([0.01, 1.0, 100.0])  # small errors, and ones that saturate the integrators
        error = [rng.gauss(0.0, scale) for _ in range(11)]
        if step % 997 == 0:
            error[rng.randrange(11)] = rng.choice([math.nan, math.inf, -math.inf])
        reset = None if step % 5 else [rng.random() < 0.2 for _ in range(11)]
        bank.step_values(error, out, reset)
        twin.step_values(error, out_twin, reset)
        assert _bits(out) == _bits(out_twin), f"step {step}"
        assert bank.clamped.tolist() == twin.clamped.tolist()
        clamped += bool(bank.clamped.any())
        if step % 1000 == 999:
            bank.reset()
            twin.reset()
    assert clamped > 100  # the anti-windup path was compared too


def test_the_smart_wheel_kinematics_compiled_computes_the_same_bits_as_its_source():
    name = "hapticop.devices.ropod.kinematics"
    compiled, source = _compiled(name), _interpreted(name)
    kin = compiled.SmartWheelKinematics()
    twin = source.SmartWheelKinematics(kin.geometry)
    assert type(kin) is not type(twin)
    rng = random.Random(3)
    singular = 0
    for trial in range(3000):
        delta = [rng.uniform(-7.0, 7.0) for _ in range(4)]
        enable = None if trial % 3 else [float(rng.random() < 0.7) for _ in range(4)]
        outcome = []
        for side in (kin, twin):
            try:
                side.evaluate(delta, enable)
                outcome.append(None)
            except np.linalg.LinAlgError as error:  # fewer than two units: both must refuse alike
                outcome.append((type(error), str(error)))
        assert outcome[0] == outcome[1], f"trial {trial}"
        if outcome[0] is not None:
            singular += 1
            continue
        assert _bits(kin._n + kin._n_inv) == _bits(twin._n + twin._n_inv)
        speeds = [rng.gauss(0.0, 20.0) for _ in range(8)]
        assert _bits(kin.twist_of(speeds)) == _bits(twin.twist_of(speeds))
        vx, vy, wz = rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 2)
        for method, size in (("wheel_speeds_into", 8), ("pivot_rates_into", 4)):
            out, out_twin = [0.0] * size, [0.0] * size
            getattr(kin, method)(vx, vy, wz, out)
            getattr(twin, method)(vx, vy, wz, out_twin)
            assert _bits(out) == _bits(out_twin), method
        torques = [rng.gauss(0.0, 5.0) for _ in range(8)]
        assert _bits(kin.wrench_of(torques)) == _bits(twin.wrench_of(torques))
        wrench, tau_max = (rng.gauss(0, 200), rng.gauss(0, 200), rng.gauss(0, 50)), rng.choice([2.0, 1e6])
        out, out_twin = [0.0] * 8, [0.0] * 8
        assert _bits([kin.distribute_into(*wrench, tau_max, out)]) == _bits(
            [twin.distribute_into(*wrench, tau_max, out_twin)])
        assert _bits(out) == _bits(out_twin)
    assert singular > 10  # the refusal was compared too


def _scan(rng: np.random.Generator, n: int) -> np.ndarray:
    """Ranges as a scanner gives them and worse: walls near and far, NaN and inf beams, zeros, ties."""
    ranges = rng.choice([rng.uniform(0.0, 3.0), 0.5, 1.25], size=n) if rng.random() < 0.2 else rng.uniform(0.0, 8.0, n)
    bad = rng.random(n)
    ranges[bad < 0.05] = np.nan
    ranges[(bad >= 0.05) & (bad < 0.07)] = np.inf
    ranges[(bad >= 0.07) & (bad < 0.08)] = 0.0
    return ranges.astype(rng.choice([np.float32, np.float64]))


@pytest.mark.parametrize("lidar_y", [0.0, 0.1, 0.45])  # 0.45: outside the body, every beam searched for both sides
def test_the_beam_loops_compiled_give_numpys_bits(lidar_y):
    """`BeamGeometry` with the compiled loops against its numpy passes (the interpreted path), over
    random scans, points given as a field (NaN ones too), shifts, margins and robust k."""
    from hapticop.devices.ropod.body import Body
    from hapticop.devices.sick.scan import SensorMount
    from hapticop.haptics.geometry import BeamGeometry

    _compiled("hapticop.haptics.beam_loops")
    rng = np.random.default_rng(7)
    body = Body(lidar=SensorMount(x_m=0.25, y_m=lidar_y))
    n = 811
    angles = np.linspace(-2.356, 2.356, n)
    loops, numpy_passes = BeamGeometry(angles, body), BeamGeometry(angles, body)
    numpy_passes._loops = None
    assert loops._loops is not None
    reached = set()
    shifts = [0.0, -0.0, 0.3, -2.0, 1e-300, math.nan, math.inf, -math.inf]
    hl, hw = body.footprint.length_m / 2, body.footprint.width_m / 2
    for trial in range(400):
        margin, k = float(rng.choice([0.0, 0.1, 0.35])), int(rng.integers(1, 6))
        rear, ahead = float(rng.uniform(0, 1)), float(rng.uniform(0, 3))
        if trial % 4 == 3:  # points given, as a scan field carries them (a bad sample may hold NaN)
            field = np.vstack([_scan(rng, n).astype(np.float64), angles,
                               rng.uniform(-3, 9, n), rng.uniform(-4, 4, n)])
            field[2:, rng.random(n) < 0.03] = np.nan
            edge = rng.random(n) < 0.2  # points exactly on the corridor's and the side window's edges
            field[2, edge] = rng.choice([hl, -hl - rear, hl + ahead], size=int(edge.sum()))
            field[3, edge] = rng.choice([hw + margin, -hw - margin, hw, -hw], size=int(edge.sum()))
            for side in (loops, numpy_passes):
                side.load_points(field)
        else:
            ranges = _scan(rng, n)
            for side in (loops, numpy_passes):
                side.load(ranges)
        gaps = [side.corridor_gap(margin, k) for side in (loops, numpy_passes)]
        assert _bits(gaps[:1]) == _bits(gaps[1:]), f"trial {trial}: corridor gap"
        for side in (loops, numpy_passes):
            side.select_sides(rear, ahead)
        assert np.array_equal(loops._left_penalty, numpy_passes._left_penalty)
        assert np.array_equal(loops._right_penalty, numpy_passes._right_penalty)
        for _ in range(6):
            sx = float(rng.choice(shifts)) if rng.random() < 0.3 else float(rng.uniform(-1, 3))
            sy = float(rng.choice(shifts)) if rng.random() < 0.3 else float(rng.uniform(-1, 1))
            k = int(rng.integers(1, 6))
            c = loops.side_clearances(sx, sy, k)
            c_numpy = numpy_passes.side_clearances(sx, sy, k)
            assert _bits(c) == _bits(c_numpy), f"trial {trial}: shift ({sx}, {sy}), k {k}"
            reached.update("nan" if math.isnan(v) else "inf" if math.isinf(v) else "finite" for v in c)
    assert reached == {"nan", "inf", "finite"}  # every kind of answer was compared


def test_the_beam_loops_compiled_and_as_written_agree_and_refuse_a_span_beyond_the_beams():
    name = "hapticop.haptics.beam_loops"
    compiled, source = _compiled(name), _interpreted(name)
    assert compiled.COMPILED and not source.COMPILED
    rng = np.random.default_rng(11)
    for trial in range(60):
        n = int(rng.integers(1, 60))
        px, py = rng.uniform(-2, 4, n), rng.uniform(-2, 2, n)
        px[rng.random(n) < 0.1] = np.nan
        valid = (rng.random(n) < 0.9).astype(np.uint8)
        lo, hi = sorted(int(v) for v in rng.integers(0, n + 1, 2))
        results = []
        for module in (compiled, source):
            buffers = module.BeamBuffers(px, py, valid, np.empty(n), np.empty(n), np.empty(n))
            gap = buffers.corridor_kth(0.4, 0.35, 2)
            buffers.select_sides(-0.8, 1.2, 0.3)
            squared = [buffers.side_kth_squared(side, lo, hi, 0.2, -0.1, 0.35, 0.3, 3) for side in (True, False)]
            results.append(([gap, *squared], np.asarray(buffers.left).tobytes(), np.asarray(buffers.right).tobytes()))
        assert _bits(results[0][0]) == _bits(results[1][0]) and results[0][1:] == results[1][1:], f"trial {trial}"
    for module in (compiled, source):  # unchecked C indexing must never be reached with a wrong span or buffer
        buffers = module.BeamBuffers(*(np.zeros(4) for _ in range(2)), np.zeros(4, np.uint8),
                                     *(np.zeros(4) for _ in range(3)))
        with pytest.raises(IndexError):
            buffers.side_kth_squared(True, 0, 5, 1.0, 0.0, 0.3, 0.3, 1)
        assert not np.asarray(buffers.work).any()  # refused before its loop wrote a beam
        with pytest.raises(IndexError):
            buffers.kth_smallest(-1, 2, 1)
        with pytest.raises(ValueError, match="every beam buffer"):
            module.BeamBuffers(*(np.zeros(4) for _ in range(2)), np.zeros(4, np.uint8), np.zeros(3),
                               *(np.zeros(4) for _ in range(2)))


# ---------------------------------------------------------------- the Falcon's kinematics and its legs
def _falcon_pair(drive: Drive):
    """The compiled FalconKinematics on compiled legs, and its source on the legs' source."""
    legs, kinematics = "hapticop.devices.falcon.legs", "hapticop.devices.falcon.kinematics"
    compiled_legs, compiled = _compiled(legs), _compiled(kinematics)
    source_legs, source = _interpreted(legs), _interpreted(kinematics)
    source.LegMaths = source_legs.LegMaths  # the source's own legs, not the compiled ones it imported
    kin, twin = compiled.FalconKinematics(drive=drive), source.FalconKinematics(drive=drive)
    assert type(kin) is not type(twin)
    assert type(kin._leg1) is compiled_legs.LegMaths and type(twin._leg1) is source_legs.LegMaths
    return kin, twin


def _result(call, *args):
    """What a call returned, or the type and message of what it raised."""
    try:
        return "returned", call(*args)
    except Exception as error:  # noqa: BLE001 - compiled and source must raise alike, whatever it is
        return "raised", type(error), str(error)


def _same(a, b) -> bool:
    """Equal results, floats (nested in tuples and arrays) compared by their bits."""
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        return a.dtype == b.dtype and _same(tuple(a.ravel().tolist()), tuple(b.ravel().tolist()))
    if isinstance(a, float) and isinstance(b, float):
        return _bits([a]) == _bits([b])
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def _position(rng: random.Random) -> tuple[float, float, float]:
    """Mostly in the workspace box, a third of them up to half its size outside, some not finite."""
    lo, hi = WORKSPACE_BOX_M
    margin = rng.choice([0.0, 0.0, 0.5])
    p = [rng.uniform(a - margin * (b - a), b + margin * (b - a)) for a, b in zip(lo, hi)]
    if rng.random() < 0.05:
        p[rng.randrange(3)] = rng.choice([math.nan, math.inf, -math.inf, 0.0])
    return p[0], p[1], p[2]


def test_the_falcon_legs_compiled_compute_the_same_bits_as_their_source():
    name = "hapticop.devices.falcon.legs"
    compiled, source = _compiled(name), _interpreted(name)
    g = Geometry()
    rng = random.Random(11)
    unreachable = singular = 0
    for phi in (*g.leg_angles_deg, 17.0):
        leg, twin = compiled.LegMaths(g, phi), source.LegMaths(g, phi)
        assert type(leg) is not type(twin)
        assert _bits([getattr(leg, a) for a in source.LegMaths.__slots__]) == _bits(
            [getattr(twin, a) for a in source.LegMaths.__slots__])
        for _ in range(2000):
            p = _position(rng)
            ik = _result(leg.ik, *p)
            assert _same(ik, _result(twin.ik, *p)), p
            unreachable += ik[1] is None
            state = ik[1] if ik[1] is not None else tuple(rng.uniform(-4.0, 4.0) for _ in range(8))
            if rng.random() < 0.1:  # thigh along the link (D = 0), or not finite
                state = (state[0], state[0], *state[2:]) if rng.random() < 0.5 else tuple(
                    rng.choice([v, math.nan, math.inf]) for v in state)
            row = _result(leg.row, state)
            assert _same(row, _result(twin.row, state)), state
            singular += row == ("returned", None)
    assert unreachable > 100 and singular > 10  # the refusals were compared too


@pytest.mark.parametrize("drive", [Drive(), Drive(motor_per_nm=-9876.54321, torque_limit_nm=0.1234567)],
                         ids=["libnifalcon's drive", "a motor cap and scale no float holds exactly"])
def test_the_falcon_kinematics_compiled_computes_the_same_bits_as_its_source(drive):
    kin, twin = _falcon_pair(drive)
    constants = ("_rad_per_count", "_zero_rad", "_motor_per_nm", "_motor_cap", "tol_rad", "tol_m", "max_condition")
    assert _bits([getattr(kin, a) for a in constants]) == _bits([getattr(twin, a) for a in constants])
    rng = random.Random(13)
    outcomes = {"forward failed": 0, "inverse failed": 0, "saturated": 0, "not finite": 0, "singular": 0,
                "raised": 0}
    theta = np.zeros(3)
    assert kin.inverse(np.array([0.0, 0.0, 0.125]), theta)
    counts = kin.counts_from_angles(theta, np.zeros(3, dtype=np.int64)).tolist()
    for trial in range(3000):
        condition = 4.0 if trial % 37 == 0 else 1e6  # now and then a Jacobian too ill-conditioned to use
        kin.max_condition = twin.max_condition = condition
        # forward: a walk of a few counts a cycle, now and then a jump, an unreachable or non-finite reading
        kind, reading, angles = rng.random(), None, None
        if kind < 0.03 and kin.inverse(_position(rng), theta):  # a jump across the workspace
            counts = kin.counts_from_angles(theta, np.zeros(3, dtype=np.int64)).tolist()
        elif kind < 0.06:  # one reading no pose gives
            reading = [rng.randrange(-30000, 30000) for _ in range(3)]
        elif kind < 0.08:
            kin.reset()
            twin.reset()
        elif kind > 0.97:
            angles = [rng.choice([0.3, math.nan, math.inf, -math.inf, 1e300]) for _ in range(3)]
        else:
            counts = [c + rng.randrange(-6, 7) for c in counts]
        outs = []
        for side in (kin, twin):
            out = np.full(3, -1.0)
            got = (_result(side.forward, np.array(reading or counts, dtype=np.int64), out) if angles is None
                   else _result(side.forward_angles, angles, out))
            outs.append((got, out.tolist(), side.iterations, side.residual, side._last))
        assert _same(outs[0][0], outs[1][0]) and _bits(outs[0][1]) == _bits(outs[1][1]), (trial, counts, angles)
        assert outs[0][2] == outs[1][2] and _same(outs[0][3:], outs[1][3:]), trial
        assert _same((kin._Q, kin._Mt, kin._det), (twin._Q, twin._Mt, twin._det)), trial  # the last Jacobian
        outcomes["forward failed"] += outs[0][0] == ("returned", False)
        # forces at the last forward pose, and at a random position
        force = [rng.gauss(0.0, rng.choice([1.0, 10.0, 1e4])) for _ in range(3)]
        if rng.random() < 0.03:
            force[rng.randrange(3)] = rng.choice([math.nan, math.inf, -math.inf])
        p = _position(rng)
        for position in (None, p):
            motors = []
            for side in (kin, twin):
                motor = np.full(3, 7, dtype=np.int64)
                motors.append((_result(side.forces_to_motor, position, force, motor), motor.tolist()))
            assert motors[0] == motors[1] and _same(motors[0][0], motors[1][0]), (trial, position, force)
            outcomes["saturated"] += max(map(abs, motors[0][1])) == int(twin._motor_cap)
            outcomes["not finite"] += motors[0][0] == ("returned", False) and not all(map(math.isfinite, force))
        tau = [rng.gauss(0.0, rng.choice([0.1, 1.0, 100.0])) for _ in range(3)]
        if rng.random() < 0.03:
            tau[rng.randrange(3)] = rng.choice([math.nan, math.inf])
        for method, args, shape, dtype in (
                ("forces_to_torques", (p, force), 3, float), ("torques_to_force", (p, tau), 3, float),
                ("torques_to_motor", (tau,), 3, np.int64), ("inverse", (p,), 3, float),
                ("jacobian", (p,), (3, 3), float), ("angles_from_counts", (counts,), 3, float)):
            results = []
            for side in (kin, twin):
                out = np.full(shape, -3, dtype=dtype)
                results.append((_result(getattr(side, method), *args, out), out.ravel().tolist()))
            assert _same(results[0][0], results[1][0]), (trial, method, args)
            assert _bits(results[0][1]) == _bits(results[1][1]) if dtype is float else results[0] == results[1]
            if method == "inverse":
                outcomes["inverse failed"] += results[0][0] == ("returned", False)
            if method == "jacobian":
                outcomes["singular"] += results[0][0] == ("returned", False) and condition == 4.0
        outs = []
        for side in (kin, twin):
            theta2, theta3 = np.zeros(3), np.zeros(3)
            outs.append((_result(side.inverse, p, np.zeros(3), theta2, theta3), theta2.tolist() + theta3.tolist()))
        assert _same(outs[0][0], outs[1][0]) and _bits(outs[0][1]) == _bits(outs[1][1]), p
        # the simulator's float-level API
        pose = _result(kin.pose, *p)
        assert _same(pose, _result(twin.pose, *p)), p
        if pose[1] is not None:
            assert _same(_result(kin.pose_force, pose[1], *tau), _result(twin.pose_force, pose[1], *tau)), p
        angles = [rng.uniform(-1.0, 2.0) for _ in range(3)]
        if rng.random() < 0.05:
            angles[rng.randrange(3)] = rng.choice([math.nan, math.inf])
        counted = _result(kin.counts_from_angles, angles, np.zeros(3, dtype=np.int64))
        assert _same(counted, _result(twin.counts_from_angles, angles, np.zeros(3, dtype=np.int64))), angles
        outcomes["raised"] += counted[0] == "raised"  # a NaN or infinite angle has no count
        assert _same(_result(kin.count, angles[0]), _result(twin.count, angles[0]))
    assert all(n > 10 for n in outcomes.values()), outcomes  # every refusal and the saturation were compared


def _channel_tokens(rng, count: int, digits: int) -> bytes:
    """`count` hex tokens of a scan channel, mostly good; some with a flaw a broken link might bring."""
    tokens = []
    for _ in range(count):
        width = int(rng.integers(1, digits + 1))
        token = "".join(rng.choice(list("0123456789ABCDEFabcdef"), size=width))
        flaw = rng.random()
        if flaw < 0.004:
            token = ""  # a double space
        elif flaw < 0.008:
            token += "F"  # one digit too many
        elif flaw < 0.012:
            token = token[:-1] + str(rng.choice(list("G-x\x00\xff.")))  # not a hex digit
        tokens.append(token)
    return " ".join(tokens).encode("latin-1")


def test_the_scan_loops_compiled_decode_a_channel_as_numpy_does():
    """`TokenReader.values` through the compiled decode against its numpy passes, over random channels:
    the same values and position, or the same error, whatever the flaw and wherever the body ends."""
    from hapticop.devices.sick import cola

    compiled = _compiled("hapticop.devices.sick.scan_loops")
    as_numpy = _interpreted("hapticop.devices.sick.scan_loops")
    assert compiled.COMPILED and not as_numpy.COMPILED
    rng = np.random.default_rng(5)
    outcomes = set()
    for trial in range(3000):
        digits = int(rng.choice([2, 4, 8]))
        count = int(rng.integers(1, 60))
        body = _channel_tokens(rng, count + int(rng.integers(-3, 4)), digits)
        lead = rng.choice([b"", b"DIST1 ", b"X "])
        body = lead + body + rng.choice([b"", b" 0 0", b" ", b"  1"])
        answers = []
        for module in (compiled, as_numpy):
            cola.scan_loops = module
            reader = cola.TokenReader(body, len(lead))
            try:
                values = reader.values(count, digits, "DIST1 values")
                answers.append(("ok", values.tolist(), values.dtype, reader.pos))
            except cola.ColaError as error:
                answers.append(("error", str(error)))
        cola.scan_loops = compiled
        assert answers[0] == answers[1], f"trial {trial}: {body!r}, {count} values of {digits} digits"
        out, written = np.zeros(count, np.uint32), np.zeros(count, np.uint32)
        after = compiled.decode_hex(body, len(lead), count, digits, out)  # and the loop as written, interpreted
        assert as_numpy.decode_hex(body, len(lead), count, digits, written) == after
        if after >= 0:
            assert out.tolist() == written.tolist() == answers[0][1]
        outcomes.add({compiled.TOO_FEW: "too few", compiled.NOT_HEX: "not hex", compiled.EMPTY: "empty",
                      compiled.TOO_WIDE: "too wide"}.get(after, "ok"))
    assert outcomes == {"ok", "too few", "not hex", "empty", "too wide"}  # every answer was compared


def test_the_scan_loops_compiled_scale_and_lay_out_as_numpy_does():
    """Whole telegrams through `parse_scan`, with the compiled loops and with numpy's passes: the same bits
    for ranges and angles over scale factors, offsets (±0 too) and minimum ranges; float32 outputs, which
    the loops do not write, give numpy's too."""
    from hapticop.devices.sick import scan

    compiled = _compiled("hapticop.devices.sick.scan_loops")
    as_numpy = _interpreted("hapticop.devices.sick.scan_loops")
    rng = np.random.default_rng(9)
    n = 811
    for trial in range(300):
        dist = scan.Channel("DIST1", float(rng.choice([1.0, 2.0, 0.1, 3.7e-5, 1e30])),
                            float(rng.choice([0.0, -0.0, 0.25, -1.5])), int(rng.integers(-1_350_000, 0)),
                            int(rng.integers(1, 5000)), n)
        header = scan.ScanHeader("sSN", 1, 1, 1, (0, 0), 1, 1, 1, 1, (0, 0), (0, 0), 0, 1500, 162,
                                 channels16=(dist,))
        raw = rng.integers(0, 1 << 16, n)
        raw[rng.random(n) < 0.1] = rng.choice([0, 1, 2, 50, 65535])
        telegram = scan.build_scan(header, raw)
        minimum = float(rng.choice([0.0, 0.05, 1.0, math.nan]))
        dtype = np.float32 if trial % 5 == 4 else np.float64
        results = []
        for module in (compiled, as_numpy):
            scan.scan_loops = module
            ranges, angles = np.empty(n, dtype), np.empty(n, dtype)
            scan.parse_scan(telegram, ranges, angles, min_range_m=minimum)
            results.append((ranges.tobytes(), angles.tobytes()))
        scan.scan_loops = compiled
        assert results[0] == results[1], f"trial {trial}: {dist}, minimum {minimum}, {dtype.__name__}"


def test_the_scan_loops_refuse_an_output_that_does_not_fit_before_writing():
    compiled, source = _compiled("hapticop.devices.sick.scan_loops"), _interpreted("hapticop.devices.sick.scan_loops")
    for module in (compiled, source):
        out = np.full(3, 7, np.uint32)
        with pytest.raises(IndexError):
            module.decode_hex(b"1 2 3 4", 0, 4, 4, out)
        assert out.tolist() == [7, 7, 7]
        assert module.decode_hex(b"1 2 3 4", 2, 3, 4, out) == 8 and out.tolist() == [2, 3, 4]
        ranges = np.full(2, 7.0)
        with pytest.raises(IndexError):
            module.scale_ranges(np.array([1, 2, 3], np.uint32), 1.0, 0.0, 0.0, ranges)
        assert ranges.tolist() == [7.0, 7.0]


def test_the_tallies_compiled_count_and_merge_as_the_runtime_did():
    """`Histograms.count` against the same counts made by numpy, and `OriginMerge.merge` against numpy's
    reduction, compiled and as written: random durations (negative, past the last bin, new maxima) and
    stamps (negative too). Once closed (the run ending), they count nothing."""
    from hapticop.runtime.timing import BINS

    name = "hapticop.runtime.tallies"
    compiled, source = _compiled(name), _interpreted(name)
    assert compiled.COMPILED and not source.COMPILED
    rng = np.random.default_rng(3)
    reference = (np.zeros((4, BINS), np.int64), np.full(4, np.iinfo(np.int64).min))
    counted = {module: (np.zeros((4, BINS), np.int64), np.zeros(4, np.int64)) for module in (compiled, source)}
    closed = np.zeros(1, np.int64)
    tallies = {module: module.Histograms(*arrays, closed) for module, arrays in counted.items()}
    values = np.concatenate([rng.integers(-5_000, 40_000_000, 3000), [0, 999, 1000, BINS * 1000 - 1, BINS * 1000,
                                                                       -1, 2**62]])
    rows = rng.integers(0, 4, values.shape[0])
    for index, value in zip(rows.tolist(), values.tolist()):
        for tally in tallies.values():
            tally.count(index, value)
    np.add.at(reference[0], (rows, np.clip(values // 1000, 0, BINS - 1)), 1)  # floor to the us, clipped to the bins
    np.maximum.at(reference[1], rows, values)
    reference[1][reference[1] < 0] = 0  # a maximum starts at 0
    for histogram, maximum in counted.values():
        assert np.array_equal(histogram, reference[0]) and np.array_equal(maximum, reference[1])
    for module in (compiled, source):
        histogram, maximum = counted[module]
        before = histogram.copy()
        for index in (-1, 4):
            with pytest.raises(IndexError):
                tallies[module].count(index, 5)
        assert np.array_equal(histogram, before)
        with pytest.raises(ValueError):
            module.Histograms(histogram, np.zeros(3, np.int64), closed)
    closed[0] = 1
    for module, tally in tallies.items():
        before = [array.copy() for array in counted[module]]
        tally.count(0, 5_000_000_000)
        assert all(np.array_equal(a, b) for a, b in zip(counted[module], before))
    for trial in range(300):
        rows, outs, width = int(rng.integers(1, 6)), int(rng.integers(0, 4)), 5
        inputs = rng.integers(-2**40, 2**40, (rows, width))
        inputs[rng.random((rows, width)) < 0.3] = 0
        expected = np.maximum.reduce(inputs, axis=0)
        for module in (compiled, source):
            newest, outputs = np.full(width, 7, np.int64), np.full((outs, width), 7, np.int64)
            module.OriginMerge(inputs, newest, outputs).merge()
            assert np.array_equal(newest, expected) and all(np.array_equal(row, expected) for row in outputs), trial
    with pytest.raises(ValueError):
        compiled.OriginMerge(np.zeros((0, 5), np.int64), np.zeros(5, np.int64), np.zeros((1, 5), np.int64))
