"""systems/wall.yaml, the virtual wall on the desk, under the virtual clock through the Falcon's real codec."""

import numpy as np
import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus, RunOptions, System
from hapticop.validation import validate_text

from .conftest import SYSTEMS
from .runtime_helpers import compose

WALL_Y, STIFFNESS, PUSH = -0.01, 1000.0, 4.0  # systems/wall.yaml's floor and the scripted hand's force


def test_the_wall_runs_from_yaml_alone_and_ends_with_its_script(tmp_path):
    result = compose(tmp_path, (SYSTEMS / "wall.yaml").read_text(), duration="20s", name="wall")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    run = tmp_path / "run-wall"
    assert "homed after" in (run / "falcon.log").read_text()  # 16-byte frames, homing bit, kinematics
    assert "the script is over" in (run / "hand.log").read_text()  # it ended by itself, long before 20 s


@pytest.fixture(scope="module")
def pushed(tmp_path_factory):
    """The handle pushed onto the wall: per cycle the true handle, the hand's and the device's force, the grip."""
    validated = validate_text((SYSTEMS / "wall.yaml").read_text(), "wall.yaml")
    assert validated.report.ok, validated.report.diagnostics
    system = System(validated, RunOptions(clock="virtual", run_dir=tmp_path_factory.mktemp("wall"), echo=False))
    main = system.built.threads["main"]
    rows = []
    try:
        system.start_threads()
        for i in range(4500):
            system.clock.advance_to(i * 1_000_000)
            main.cycle()
            if system.state("falcon").flag_name == "running":
                block = {name: main.runners[name].block for name in ("falcon_sim", "hand", "limit", "grip")}
                rows.append((block["falcon_sim"].outputs.handle_position.value[1],
                             block["hand"].outputs.hand_force.value[1], block["limit"].outputs.force.value[1],
                             int(block["grip"].outputs.pressed.value)))
    finally:
        for runner in main.runners.values():
            runner.block.clean()
        system.writer.stop()
        system.built = system.main = None
        system.region.close()
    return np.array(rows)


def test_the_handle_pushed_into_the_wall_penetrates_is_pushed_back_and_does_not_pass_through(pushed):
    y, hand, device, grip = pushed.T
    holding = np.flatnonzero(hand == -PUSH)
    assert holding.size > 1000  # the scripted hand held 4 N down for over a second
    settled = holding[holding > holding[0] + 500]
    assert (y[settled] < WALL_Y).all()  # it penetrates
    assert (device[settled] > 0).all()  # and the wall pushes back up, against the hand
    assert y.min() > WALL_Y - 2 * PUSH / STIFFNESS  # never through: at most twice the static depth, on impact
    depth = WALL_Y - np.median(y[settled])
    assert depth == pytest.approx(PUSH / STIFFNESS, rel=0.2)  # a wall of about the declared stiffness
    assert (device[y > WALL_Y + 1e-3] == 0).all()  # nothing in front of it


def test_the_grip_button_reaches_the_dead_man_through_the_falcon_frames(pushed):
    y, hand, device, grip = pushed.T
    assert grip[hand == -PUSH].all()  # the scripted hand holds button 1 while it pushes: frames carry it
    released = np.flatnonzero((hand == 0) & (np.arange(len(hand)) > np.flatnonzero(hand == -PUSH)[-1]))
    assert not grip[released[30:]].any()  # let go: released, after the debounce
    assert (device[released[30:]] == 0).all()  # and the device renders nothing
