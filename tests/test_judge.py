"""The judge users configure: each task target met by one run on a tiny scene and missed by another,
the generic metrics of the run, and a target naming an unknown body refused at validation where it
is written. The runs are the scene world's own, under the virtual clock."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from hapticop.runtime.clock import VirtualClock
from hapticop.sim.judge import Target
from hapticop.sim.scene import Block3, Movable, Robot, Scene
from hapticop.sim.scene_world import SceneWorld
from hapticop.validation import validate_path

from .runtime_helpers import standalone

# A crate ahead of the robot, a wall behind it at x = 4 (its face at 3.95); the robot (0.7 m by 0.6 m)
# starts at x = 0.5.
PUSH = Scene(walls=(Block3(name="end", size_m=(0.1, 4.0, 1.0), position_m=(4.0, 0.0)),),
             bodies=(Movable(name="crate", size_m=(0.4, 0.4, 0.4), position_m=(1.6, 0.0), mass_kg=2.0),),
             robot=Robot(start=(0.5, 0.0, 0.0)))
# A wall the robot drives into: its front starts at 0.85, the wall's face is at 1.45.
WALL = Scene(walls=(Block3(size_m=(0.1, 4.0, 1.0), position_m=(1.5, 0.0)),), robot=Robot(start=(0.5, 0.0, 0.0)))


def _run(tmp_path, scene: Scene, targets: list, travel_m: float, speed_mps: float = 0.5,
         hold_s: float = 0.5, plot: bool = False) -> dict:
    """The robot driven straight ahead `travel_m` at `speed_mps`, then held still; the world's judge.json."""
    clock = VirtualClock()
    world = standalone(SceneWorld, "world", {"scene": scene.model_dump(), "judge": False, "plot": plot,
                                             "targets": targets}, tmp_path, clock)
    world.create()
    pose, twist = world.inputs.robot_pose, world.inputs.robot_twist
    x, steps = 0.0, int(round(travel_m / speed_mps * 1000)) + int(hold_s * 1000)
    for i in range(steps):
        clock.advance_to(clock.now_ns() + 1_000_000)
        v = speed_mps if x < travel_m - 1e-9 else 0.0
        x = min(travel_m, x + v * 1e-3)
        pose.value[:] = (x, 0.0, 0.0)
        twist.value[:] = (v, 0.0, 0.0)
        pose.meta[0] = twist.meta[0] = i + 1
        world.compute()
    world.clean()
    return json.loads((tmp_path / "judge.json").read_text())


def _verdicts(judged: dict) -> list[bool]:
    return [row["ok"] for row in judged["targets"]]


@pytest.fixture(scope="module")
def pushed(tmp_path_factory):
    """One run that pushes the crate 1.5 m ahead and stops 1.6 m before the wall; each target asked twice:
    once met, once missed."""
    targets = [
        {"reach": {"region": {"circle": {"center_m": [2.0, 0.0], "radius_m": 0.1}}}},
        {"reach": {"region": {"box": {"min_m": [1.5, 0.5], "max_m": [3.0, 1.0]}}}},
        {"stop_before": {"line": [[3.95, -2.0], [3.95, 2.0]], "margin_m": 1.5}},
        {"stop_before": {"line": [[3.95, -2.0], [3.95, 2.0]], "margin_m": 1.7}},
        {"stop_before": {"line": [[3.95, 2.0], [3.95, -2.0]], "margin_m": 1.5, "within_m": 0.2}},
        {"stop_before": {"line": [[3.95, -2.0], [3.95, 2.0]], "margin_m": 1.5, "within_m": 0.05}},
        {"keep_clearance": {"min_m": 1.55}},
        {"keep_clearance": {"min_m": 1.65}},
        {"push_body": {"body": "crate", "to": {"box": {"min_m": [2.5, -0.3], "max_m": [3.0, 0.3]}}}},
        {"push_body": {"body": "bodies[0]", "to": {"circle": {"center_m": [1.6, 0.0], "radius_m": 0.5}}}},
        "no_collision",
        {"time_within": {"max_s": 3.1}},
        {"time_within": {"max_s": 2.9}},
        {"metric": {"name": "path_length_m", "min": 1.4, "max": 1.6}},
        {"metric": {"name": "path_length_m", "max": 1.0}},
    ]
    return _run(tmp_path_factory.mktemp("pushed"), PUSH, targets, travel_m=1.5)


@pytest.mark.parametrize("kind, met, missed", [("reach", 0, 1), ("stop_before", 2, 3),
                                               ("stop_before (ending near)", 4, 5), ("keep_clearance", 6, 7),
                                               ("push_body", 8, 9), ("time_within", 11, 12),
                                               ("metric", 13, 14)])
def test_each_target_is_met_by_the_run_that_meets_it_and_missed_otherwise(pushed, kind, met, missed):
    rows = pushed["targets"]
    assert rows[met]["ok"] is True, rows[met]
    assert rows[missed]["ok"] is False, rows[missed]


def test_the_generic_metrics_of_a_push(pushed):
    m = pushed["metrics"]
    assert m["path_length_m"] == pytest.approx(1.5, abs=1e-3)  # from the first recorded cycle
    assert m["collisions"] == 0 and pushed["targets"][10]["ok"] is True
    assert m["least_clearance_m"] == pytest.approx(3.95 - 2.35, abs=1e-3)  # the front at 2.35, by MuJoCo
    assert m["contact_force_peak_n"] > 1.0  # the crate pushed back
    assert 0.0 < m["contact_force_mean_n"] < m["contact_force_peak_n"]
    assert m["at_rest_after_s"] == pytest.approx(3.0, abs=0.01)
    assert m["handle_force_peak_n"] == 0.0  # no handle in this run
    assert pushed["ok"] is False  # some of its targets are missed on purpose


def test_a_run_into_a_wall_misses_no_collision(tmp_path):
    judged = _run(tmp_path, WALL, ["no_collision", {"keep_clearance": {"min_m": 0.0}}], travel_m=0.7, plot=True)
    assert judged["metrics"]["collisions"] == 1
    assert judged["metrics"]["least_clearance_m"] <= 0.0
    assert _verdicts(judged) == [False, False]
    results = json.loads((tmp_path / "results.json").read_text())
    assert [r["ok"] for r in results["rows"] if r["ok"] is not None] == [False, False]
    assert results["picture"] == "run.png" and (tmp_path / "run.png").stat().st_size > 10_000  # path and walls


def test_the_scenes_walls_are_drawn_from_the_compiled_scene():
    from hapticop.sim import scene_files
    from hapticop.sim.engine import Engine
    from hapticop.sim.plot import scene_outlines

    loaded, _ = scene_files.load("H4")
    outlines = scene_outlines(Engine(loaded.xml))
    assert len(outlines) == 4  # left, right, end, pillar
    pillar = outlines[3]
    assert pillar.min(axis=0).tolist() + pillar.max(axis=0).tolist() == pytest.approx([4.8, -1.0, 5.2, -0.75])


def test_a_target_is_one_kind():
    with pytest.raises(ValidationError, match="reach, no_collision given together"):
        Target.model_validate({"reach": {"region": {"circle": {"center_m": [0, 0], "radius_m": 1}}},
                               "no_collision": {}})
    with pytest.raises(ValidationError, match="a box or a circle"):
        Target.model_validate({"reach": {"region": {}}})


def _app(tmp_path, targets: str) -> str:
    (tmp_path / "room.yaml").write_text("""walls:
  - {name: north, size_m: [6.0, 0.1, 1.0], position_m: [3.0, 2.05]}
bodies:
  - {name: crate, size_m: [0.4, 0.4, 0.4], position_m: [2.0, 0.0], mass_kg: 10.0}
""")
    path = tmp_path / "app.yaml"
    path.write_text(f"""version: 1
name: app
threads:
  sim:
    period: 1ms
    deploy: main
    schedules: {{0: [mediator, world]}}
activities:
  mediator: {{block: mediator}}
  world:
    block: scene_world
    params:
      scene: room.yaml
      judge: false
      targets:
        - no_collision
{targets}
""")
    return str(path)


def test_a_target_naming_an_unknown_body_is_located(tmp_path):
    good = validate_path(_app(tmp_path, "        - push_body: {body: crate, to: {circle: {center_m: [3, 0], "
                                        "radius_m: 0.5}}}")).report
    assert good.ok, [d.to_text() for d in good.diagnostics]
    report = validate_path(_app(tmp_path, "        - push_body: {body: crat, to: {circle: {center_m: [3, 0], "
                                          "radius_m: 0.5}}}")).report
    (error,) = report.errors
    assert error.rule == "scene-target" and "crat" in error.message and "crate" in error.expected
    assert error.path == ("activities", "world", "params", "targets", 1, "push_body", "body")
    assert error.file.endswith("app.yaml") and error.line == 17 and error.column == 29  # at the name


def test_a_malformed_target_is_located(tmp_path):
    report = validate_path(_app(tmp_path, "        - reach: {region: {box: {min_m: [1, 1], max_m: [0, 0]}}}")).report
    assert not report.ok
    assert any(e.line == 17 for e in report.errors), [e.to_text() for e in report.errors]


def test_a_metric_bound_reads_its_metric_and_says_when_it_was_not_measured():
    from hapticop.sim.judge import MetricBound

    side = MetricBound(name="side_clearance_min_m", min=-0.10, relative_to="dist1_m")
    assert side.verdict({"side_clearance_min_m": 0.31}, {"dist1_m": 0.4}) == (0.31, True, False)
    assert side.verdict({"side_clearance_min_m": 0.29}, {"dist1_m": 0.4})[1] is False
    assert side.text({"dist1_m": 0.4}) == ">= 0.30"
    assert MetricBound(name="crash", equals=False).verdict({"crash": True})[1] is False
    assert MetricBound(name="x", max=1.0).verdict({"x": float("nan")}) == (pytest.approx(float("nan"), nan_ok=True),
                                                                            None, False)
    cautious = MetricBound(name="e_stop_m", min=-0.05, max=0.25, operators=("cautious",))
    assert cautious.applies("cautious") and not cautious.applies("nominal")
    assert cautious.text() == "-0.05 to +0.25"
    with pytest.raises(ValidationError, match="needs min, max or equals"):
        MetricBound(name="x")
    with pytest.raises(ValidationError, match="equals goes alone"):
        MetricBound(name="x", equals=0, max=1.0)


ROOM_WITH_TASK = """walls:
  - {name: north, size_m: [6.0, 0.1, 1.0], position_m: [3.0, 2.05]}
  - {name: end, size_m: [0.1, 4.0, 1.0], position_m: [6.05, 0.0]}
hallway: {name: room, end_wall: [%s], middle_x_m: 3.0}
targets: %s
"""


def test_a_scene_names_a_file_of_targets_and_what_is_wrong_is_located(tmp_path):
    from hapticop.sim import scene_files

    (tmp_path / "goals.yaml").write_text("doc: mine\ntargets:\n  - metric: {name: collisions, equals: 0}\n")
    (tmp_path / "room.yaml").write_text(ROOM_WITH_TASK % ("end", "goals.yaml"))
    loaded, found = scene_files.load("room.yaml", tmp_path)
    assert found == [] and loaded.scene.targets[0].metric.name == "collisions"
    shipped, found = scene_files.load("H2")
    assert found == [] and len(shipped.scene.targets) == 21  # §6's: hapticop/sim/scenes/targets/hallway.yaml

    (tmp_path / "goals.yaml").write_text("targets:\n  - metric: {name: collisions, equal: 0}\n")
    _, (error,) = scene_files.load("room.yaml", tmp_path)
    assert error.file.endswith("goals.yaml") and error.line == 2 and "equal" in error.to_text()

    (tmp_path / "room.yaml").write_text(ROOM_WITH_TASK % ("end", "missing.yaml"))
    _, (error,) = scene_files.load("room.yaml", tmp_path)
    assert error.rule == "scene-targets" and error.file.endswith("room.yaml") and error.line == 5
    assert "hallway" in error.message  # the shipped ones are named

    (tmp_path / "room.yaml").write_text(ROOM_WITH_TASK % ("ending", "goals.yaml"))
    _, (error,) = scene_files.load("room.yaml", tmp_path)
    assert error.rule == "scene-task" and error.line == 4 and "ending" in error.message and "end" in error.expected


def test_a_bound_relative_to_a_hallway_distance_needs_a_hallway_task(tmp_path):
    report = validate_path(_app(tmp_path, "        - metric: {name: least_clearance_m, min: -0.1, "
                                          "relative_to: dist1_m}")).report
    (error,) = report.errors
    assert error.rule == "scene-target" and "dist1_m" in error.message and error.line == 17
    from hapticop.sim.judge import MetricBound

    lone = MetricBound(name="least_clearance_m", min=-0.1, relative_to="dist1_m")
    assert lone.verdict({"least_clearance_m": 0.5}) == (0.5, None, False)  # no task: no verdict, no error
