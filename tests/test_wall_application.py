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


def run_wall(run_dir, cycles: int, at_cycle=None) -> np.ndarray:
    """systems/wall.yaml stepped by hand: per running cycle the true handle height, the hand's and the
    device's vertical force and the grip; `at_cycle(i, runners)` may change something on the way."""
    validated = validate_text((SYSTEMS / "wall.yaml").read_text(), "wall.yaml")
    assert validated.report.ok, validated.report.diagnostics
    system = System(validated, RunOptions(clock="virtual", run_dir=run_dir, echo=False))
    main = system.built.threads["main"]
    rows = []
    try:
        system.start_threads()
        for i in range(cycles):
            system.clock.advance_to(i * 1_000_000)
            main.cycle()
            if system.state("falcon").flag_name == "running":
                block = {name: runner.block for name, runner in main.runners.items()}
                if at_cycle is not None:
                    at_cycle(i, block)
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


@pytest.fixture(scope="module")
def pushed(tmp_path_factory):
    """The handle pushed onto the wall by the scripted hand, held, and let go."""
    return run_wall(tmp_path_factory.mktemp("wall"), 4500)


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


def test_when_the_falcons_frames_stop_the_grip_reads_released_and_the_force_ramps_to_zero(tmp_path):
    silenced = []

    def silence_mid_hold(i, block):
        if not silenced and block["hand"].outputs.hand_force.value[1] == -PUSH:
            silenced.append(i)
        if len(silenced) == 1 and i == silenced[0] + 500:  # half a second into the hold
            sim = block["falcon_sim"]
            sim.params = sim.context.params = sim.params.model_copy(update={"sim_fault": "silent"})
            silenced.append(i)

    y, hand, device, grip = run_wall(tmp_path, 3200, silence_mid_hold).T
    assert len(silenced) == 2
    frozen = np.flatnonzero(hand == -PUSH)[500:]  # the hand still pushes, but no frame comes back
    assert frozen.size > 500  # and the Falcon block still runs (it says the frames stopped)
    assert grip[frozen[:15]].all() and device[frozen[:15]].min() > 3.0  # within the streams' 20 ms max_age
    assert not grip[frozen[40:]].any() and (device[frozen[40:]] == 0).all()
