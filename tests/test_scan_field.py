"""The scan rendered beside the loop (hapticop/haptics/scan_field.py, blocks/scan_field.py) against the
scan rendered in the loop: the same forces and governed setpoints, for real captures and cast hallways,
every force model and both filters; no force from a stale or missing scan; nothing allocated per cycle."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hapticop.devices.sick import scan
from hapticop.haptics.force_models import (
    BrakingFieldParams,
    NoForceParams,
    ThesisParams,
    make_force_model,
)
from hapticop.haptics.geometry import BeamGeometry
from hapticop.haptics.governor import GovernorParams, govern_field, govern_scan
from hapticop.haptics.scan_field import ANGLE, RANGE, ScanField
from hapticop.haptics.scan_filter import MovingAverageParams, MovingMedianParams, make_scan_filter
from hapticop.testing import BlockHarness, allocation_stats

from .scans import hallway, robot_scan, tim561_angles
from .test_sick_cola import SCANS, ident

MODELS = [NoForceParams(), ThesisParams(), ThesisParams(kind="thesis_corrected"), BrakingFieldParams(),
          BrakingFieldParams(silent_ratio=0.9, brake_decel_mps2=0.8, proximity_gap_m=0.1, z_ramp_m=0.01,
                             side_risk_rate_per_s=3.0, fx_max_n=7.0)]
FILTERS = [MovingAverageParams(window=3), MovingMedianParams(window=5)]
# (handle x, y, z), measured twist, predicted travel: pushed and steered, at standstill, and reversing
CYCLES = [((0.0, 0.0, -0.03), (0.6, 0.0, 0.0), None), ((0.02, 0.0, -0.01), (0.3, 0.05, 0.2), (0.05, 0.01, 0.0)),
          ((-0.03, 0.0, 0.02), (-0.2, 0.0, -0.1), None), ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.3, -0.02, 0.0))]


def _captured() -> list[tuple[str, np.ndarray, np.ndarray]]:
    found = []
    for path in SCANS:
        ranges, angles = np.empty(scan.TIM561_POINTS, np.float32), np.empty(scan.TIM561_POINTS, np.float32)
        scan.parse_scan(path.read_bytes(), ranges, angles)
        found.append((ident(path), ranges, angles))
    return found


def _cast() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Hallways near enough for every model to push: the end wall 1 m ahead, a side wall 0.2 m off."""
    angles = tim561_angles().astype(np.float32)
    found = []
    for name, pose in (("end-ahead", (0.0, 0.0, 0.0)), ("near-left", (0.0, 0.35, 0.1)),
                       ("near-right", (0.5, -0.4, -0.2))):
        ranges = robot_scan(angles.astype(np.float64), hallway(1.5, 1.8), pose).astype(np.float32)
        found.append((name, ranges, angles))
    return found


SCENES = _captured() + _cast()


@pytest.mark.parametrize("scene", SCENES, ids=[s[0] for s in SCENES])
@pytest.mark.parametrize("filter_params", FILTERS, ids=lambda f: f.kind)
@pytest.mark.parametrize("model_params", MODELS, ids=lambda m: m.kind)
def test_the_force_from_the_field_is_the_force_from_the_scan(scene, filter_params, model_params):
    """Cycle by cycle (the rate limiters carry state) the two models write the same force, and the
    governor finds the same stop gap."""
    _, ranges, angles = scene
    old_filter = make_scan_filter(filter_params)
    old = make_force_model(model_params, old_filter.configure(angles))
    renderer = ScanField(filter_params, angles)
    field = renderer.apply(ranges)
    new = make_force_model(model_params, field[ANGLE])
    filtered = old_filter.apply(ranges)
    old.update_scan(filtered)
    new.update_field(field)
    np.testing.assert_array_equal(field[RANGE, : filtered.shape[0]], filtered)
    assert np.isnan(field[RANGE, filtered.shape[0]:]).all()
    out_old, out_new = np.zeros(3), np.zeros(3)
    for _ in range(3):
        for handle, twist, travel in CYCLES:
            h, t = np.array(handle), np.array(twist)
            tr = None if travel is None else np.array(travel)
            old.render(h, t, out_old, 0.03, tr)
            new.render(h, t, out_new, 0.03, tr)
            np.testing.assert_allclose(out_new, out_old, rtol=0, atol=1e-12)
    governor = GovernorParams(window_ahead_m=1.0)  # a window of its own: the governor loads the points itself
    gap_old = govern_scan(filtered, BeamGeometry(old_filter.configure(angles)), governor)
    gap_new = govern_field(field, BeamGeometry(field[ANGLE]), governor)
    assert gap_new == gap_old


def test_the_cast_scenes_push():
    """The comparison above means something: near the walls the braking field pushes on both axes."""
    _, ranges, angles = SCENES[-2]
    renderer = ScanField(MovingAverageParams(), angles)
    model = make_force_model(BrakingFieldParams(), renderer.apply(ranges)[ANGLE])
    model.update_field(renderer.field)
    out = np.zeros(3)
    for _ in range(500):
        model.render(np.array([0.0, 0.0, -0.03]), np.array([0.6, 0.0, 0.0]), out)
    assert out[0] != 0.0 and out[2] != 0.0


def _haptic(fed_by: str, max_age_ns: int = 200_000_000) -> BlockHarness:
    params = {"governor": {"window_ahead_m": 1.0}, "scan_points": 811,
              "force_model": {"kind": "braking_field", "fx_max_n": 7.0}}
    harness = BlockHarness("haptic_controller", params, max_age_ns={"scan_field": max_age_ns, "ranges": max_age_ns})
    harness.flags["resources_ready"] = True
    harness.feed("handle_position", [0.0, 0.0, 0.0])
    harness.feed("handle_velocity", [0.0, 0.0, 0.0])
    harness.feed("platform_velocity", [0.6, 0.0, 0.0])
    return harness


def _scan_field_block() -> BlockHarness:
    block = BlockHarness("scan_field", {"scan_filter": {"kind": "moving_average", "window": 3}})
    block.configure()
    return block


def _rendered(scene: int) -> BlockHarness:
    """The scan_field block after rendering the scan of SCENES[scene]."""
    renderer = _scan_field_block()
    _, ranges, angles = SCENES[scene]
    renderer.feed("ranges", ranges)
    renderer.feed("angles", angles)
    renderer.step()
    return renderer


def _haptic_fed_from(renderer: BlockHarness) -> BlockHarness:
    """A configured haptic controller that holds the renderer's field."""
    harness = _haptic("field")
    harness.feed("scan_field", renderer.outputs.field.value)
    harness.configure()
    return harness


def test_the_haptic_controller_fed_by_the_block_commands_and_pushes_as_fed_by_the_scan():
    """The blocks as the hallway wires them: the scan_field block on the LIDAR's side, the haptic
    controller reading its field; against the controller filtering the same scans itself."""
    renderer = _scan_field_block()
    by_field, by_scan = _haptic("field"), _haptic("scan")
    scenes = [s for s in SCENES if not s[0].startswith(("local", "shared"))]
    first, pushed = True, 0.0
    for _, ranges, angles in scenes:
        renderer.feed("ranges", ranges)
        renderer.feed("angles", angles)
        renderer.step()
        by_field.feed("scan_field", renderer.outputs.field.value)
        by_scan.feed("ranges", ranges)
        by_scan.feed("angles", angles)
        if first:
            by_field.configure()
            by_scan.configure()
            first = False
        for handle in ([0.0, 0.0, -0.03], [0.02, 0.0, -0.02], [-0.02, 0.0, 0.0]):
            for harness in (by_field, by_scan):
                harness.feed("handle_position", handle)
            for _ in range(20):
                by_field.step()
                by_scan.step()
                for port in ("force", "environment_force", "velocity_setpoint"):
                    np.testing.assert_allclose(getattr(by_field.outputs, port).value,
                                               getattr(by_scan.outputs, port).value, rtol=0, atol=1e-12)
                pushed = max(pushed, float(np.abs(by_field.outputs.environment_force.value).max()))
    assert pushed > 1.0  # the walls were felt: the comparison compared forces, not zeros
    assert by_field.block.use_field and not by_scan.block.use_field


def test_a_stale_or_missing_field_gives_no_force_and_blinds():
    harness = _haptic_fed_from(_rendered(-3))  # the end wall ahead: the braking field pushes
    harness.feed("handle_position", [0.0, 0.0, -0.03])
    harness.step(150)  # within the field's 200 ms
    assert harness.outputs.environment_force.value[2] != 0.0 and not harness.flags["blind"]
    harness.advance(250_000_000)  # the field is now older than its 200 ms
    harness.step()
    assert (harness.outputs.environment_force.value == 0.0).all() and harness.flags["blind"]
    missing = _haptic("field")  # no scan ever: nothing to feel
    missing.configure()
    missing.feed("handle_position", [0.0, 0.0, -0.03])
    missing.step(50)
    assert (missing.outputs.environment_force.value == 0.0).all() and missing.flags["blind"]


def test_the_loops_step_and_the_scan_arrival_allocate_nothing():
    renderer = _rendered(-1)
    harness = _haptic_fed_from(renderer)
    harness.feed("handle_position", [0.01, 0.0, -0.03])
    harness.step(10)
    retained, peak = allocation_stats(harness.block.compute, 2000)
    assert retained < 256 and peak < 2048, (retained, peak)
    model, field = harness.block.model, renderer.outputs.field.value
    retained, peak = allocation_stats(lambda: model.update_field(field), 200)
    assert retained < 256 and peak < 2048, (retained, peak)


def test_a_new_filter_renders_the_next_scan():
    renderer = _rendered(0)
    _, ranges, angles = SCENES[0]
    assert np.isnan(renderer.outputs.field.value[RANGE, 809:]).all()  # 811 beams, 3-beam mean: 809
    renderer.retune({"scan_filter": {"kind": "moving_median", "window": 5}})
    renderer.feed("ranges", ranges)
    renderer.step()
    expected = ScanField(MovingMedianParams(window=5), angles).apply(ranges)
    np.testing.assert_array_equal(renderer.outputs.field.value, expected)


# -- the scan declared once: raw or rendered, and its filter where it is applied --------------------

HALLWAY = Path(__file__).resolve().parent.parent / "systems" / "hallway.yaml"


@pytest.mark.parametrize(("layer", "rule", "line"), [
    # the filter declared on the controller as well as on scan_field: the controller's would do nothing
    ("activities:\n  haptic:\n    params:\n      scan_filter: {kind: moving_median, window: 5}\n", "param-unused", 5),
    # the raw scan and the rendered one both fed to the controller
    ("streams:\n  scan_ranges:\n    to: [scan_field.ranges, haptic.ranges]\n", "inputs-alternative", None),
    # neither: the controller would run blind for ever
    ("streams:\n  rendered_scan: null\n", "input-unconnected", None),
])
def test_a_scan_declared_twice_or_not_at_all_is_refused_where_it_is_written(tmp_path, layer, rule, line):
    from hapticop.validation import validate_path

    layer_file = tmp_path / "layer.yaml"
    layer_file.write_text(f"extends: {HALLWAY}\n{layer}")
    errors = validate_path(layer_file).report.errors
    assert [d.rule for d in errors] == [rule], errors
    assert errors[0].line > 0 and errors[0].file
    if line is not None:
        assert (Path(errors[0].file).name, errors[0].line) == ("layer.yaml", line)


def test_the_controllers_own_filter_serves_its_raw_scan(tmp_path):
    """Where the raw scan is fed (teleop: the ranges cross the link), the controller's filter counts."""
    from hapticop.validation import validate_path

    layer_file = tmp_path / "layer.yaml"
    layer_file.write_text(f"extends: {HALLWAY.parent / 'teleop_sim.yaml'}\nactivities:\n  haptic:\n    params:\n"
                          "      scan_filter: {kind: moving_median, window: 5}\n")
    assert validate_path(layer_file).report.ok
