"""systems/push_box.yaml, "feel how heavy" (thesis §8.1), under the virtual clock: the robot pushes the box, and the
hand feels a heavier box push back harder (its streams recorded and read back)."""

import numpy as np
import pytest

from hapticop.recording.reading import series_of
from hapticop.runtime.system import ExitStatus

from .conftest import SYSTEMS
from .runtime_helpers import compose

BOX = "mass_kg: 10.0, material: wood, friction: 0.5}"  # scenes/push_box.yaml's box


def push(tmp_path, mass_kg: float) -> tuple[np.ndarray, np.ndarray]:
    """systems/push_box.yaml with its box of `mass_kg`, by YAML alone: the felt force (device frame) and the box's
    poses, recorded."""
    (tmp_path / "hallway.yaml").write_text((SYSTEMS / "hallway.yaml").read_text())  # what push_box.yaml extends
    scene = (SYSTEMS / "scenes" / "push_box.yaml").read_text()
    assert BOX in scene
    named = f"box_{mass_kg:g}kg.scene.yaml"  # beside the composition: each run reads its own
    (tmp_path / named).write_text(scene.replace(BOX, f"mass_kg: {mass_kg}, material: wood, friction: 0.5}}"))
    text = (SYSTEMS / "push_box.yaml").read_text().replace("scene: scenes/push_box.yaml", f"scene: {named}")
    result = compose(tmp_path, text, duration="40s", name="push_box",
                     record=str(tmp_path / "push.mcap"))
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert "the script is over" in (tmp_path / "run-push_box" / "hand.log").read_text()  # it ended by itself
    streams = series_of(tmp_path / "push.mcap", ["felt_push", "box_pose"])
    return streams["felt_push"].values, streams["box_pose"].values[:, 0, :]


def felt_while_touching(felt: np.ndarray) -> float:
    """The mean force towards the operator from the robot's first touch of the box to its last."""
    touching = np.flatnonzero(felt[:, 2] > 0.0)
    assert touching.size > 100, "the robot never pushed the box"
    return float(felt[touching[0]:touching[-1] + 1, 2].mean())


@pytest.fixture(scope="module")
def light(tmp_path_factory):
    return push(tmp_path_factory.mktemp("light"), 5.0)


@pytest.fixture(scope="module")
def heavy(tmp_path_factory):
    return push(tmp_path_factory.mktemp("heavy"), 15.0)


@pytest.mark.timeout(360)  # whole runs: a bound on hangs on a busy machine, not a speed
def test_the_robot_pushes_the_box_and_the_hand_feels_it_towards_the_operator(light):
    felt, box = light
    assert box[-1, 0] - box[0, 0] > 1.0  # the box slid a metre and more along x, straight ahead
    assert abs(box[-1, 1]) < 0.2
    assert felt[:, 2].max() > 0.1  # the push reaches the handle, towards the operator (+z)
    assert felt[:, 2].min() >= 0.0  # and never pulls the hand forward


@pytest.mark.timeout(360)
def test_a_heavier_box_is_felt_heavier_and_goes_less_far(light, heavy):
    (felt_light, box_light), (felt_heavy, box_heavy) = light, heavy
    assert box_heavy[-1, 0] - box_heavy[0, 0] > 0.2  # it still moves
    assert felt_while_touching(felt_heavy) > 2.0 * felt_while_touching(felt_light)  # three times the friction
    assert box_heavy[-1, 0] < box_light[-1, 0]  # the same hand pushes it less far


def test_a_box_that_explodes_stops_the_run_at_once_with_one_message(tmp_path):
    """push_box.yaml ends its run on the script's end and on the world's: a scene that explodes (its box thrown
    out by a gravity of 1e9, as an MJCF scene may say) stops the run, not the script 8 s later."""
    from hapticop.sim import scene_files

    (tmp_path / "hallway.yaml").write_text((SYSTEMS / "hallway.yaml").read_text())
    loaded, found = scene_files.load(SYSTEMS / "scenes" / "push_box.yaml")
    assert loaded is not None, found
    (tmp_path / "thrown.xml").write_text(loaded.xml.replace('integrator="implicitfast"/>',
                                                            'integrator="implicitfast" gravity="0 0 1e9"/>'))
    text = (SYSTEMS / "push_box.yaml").read_text().replace("scene: scenes/push_box.yaml", "scene: thrown.xml")
    result = compose(tmp_path, text, duration="40s", name="thrown")
    assert result.outcome.status is ExitStatus.FAILURE
    assert result.outcome.reasons[0] == "'world' failed (running failed)", result.outcome.reasons
    assert result.timing["activities"]["mediator"]["steps"] < 4000  # the script alone would run 8 s
    logs = "\n".join(path.read_text() for path in sorted((tmp_path / "run-thrown").glob("*.log")))
    assert "Traceback" not in logs
    [said] = [line for line in logs.splitlines() if "exploded" in line]
    assert "thrown.xml: bodies[0]" in said and "left the scene" in said
