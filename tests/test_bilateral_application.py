"""systems/bilateral.yaml: two simulated Falcons coupled position-position, under the virtual clock through
their real frame codec, the follower's handle a body of a MuJoCo scene with a wall in it. The leader's
hand feels the follower's wall, and nothing in free space; the follower stays out of the wall but for the
contact's give, and the contact's force is the scene's declared spring and damper on the depth."""

import numpy as np
import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus

from .conftest import SYSTEMS
from .runtime_helpers import compose, step_thread

# systems/scenes/bilateral.yaml: the handle's sphere touches the wall at device z = -0.02 m, 2000 N/m, 2 N s/m
WALL_Z, STIFFNESS, DAMPING = -0.02, 2000.0, 2.0
PUSH = 3.0  # systems/bilateral.yaml's leader's hand's push


def test_the_bilateral_set_up_runs_from_yaml_alone_and_ends_with_its_script(tmp_path):
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "bilateral.yaml").write_text((SYSTEMS / "scenes" / "bilateral.yaml").read_text())
    result = compose(tmp_path, (SYSTEMS / "bilateral.yaml").read_text(), duration="20s", name="bilateral")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    assert "the script is over" in (tmp_path / "run-bilateral" / "hand.log").read_text()


@pytest.fixture(scope="module")
def pushed(tmp_path_factory):
    """Per cycle once both Falcons run: leader and follower true z, the hand's z force, the leader's felt z
    force, the follower's felt wall force (z), the contacts' force on the scene's handle (x, y, z) and the
    follower position and velocity the handle was put at (z)."""
    def sample(b):
        world = b["world"].inputs
        return (b["leader_sim"].outputs.handle_position.value[2], b["follower_sim"].outputs.handle_position.value[2],
                b["hand"].outputs.hand_force.value[2], b["coupling"].outputs.leader_force.value[2],
                b["touch"].outputs.force.value[2], *b["world"].outputs.follower_handle_force.value,
                world.follower_handle_position.value[2],
                world.follower_handle_velocity.value[2])
    rows = step_thread(tmp_path_factory.mktemp("bilateral"), SYSTEMS / "bilateral.yaml", 6000, sample,
                       gate="follower")
    return np.array(rows)


def test_the_leaders_hand_feels_the_followers_wall(pushed):
    leader, follower, hand, felt, wall, *_ = pushed.T
    holding = np.flatnonzero(hand == -PUSH)
    assert holding.size > 1500  # the hand held 3 N towards the wall for two seconds
    settled = holding[holding > holding[0] + 500]
    assert (wall[settled] > 0).all()  # the follower is against the wall, pushed back by it
    assert (leader[settled] < follower[settled]).all()  # the leader went further: the coupling is stretched
    assert (felt[settled] > 0.8 * PUSH).all()  # and pushes the hand back, towards the operator, nearly its push
    assert np.median(felt[settled]) == pytest.approx(PUSH, rel=0.1)  # at rest the hand's push is all met by the wall


def test_the_follower_stays_out_of_the_wall_but_for_the_contacts_give(pushed):
    _, follower, hand, _, wall, *_ = pushed.T
    # homing presses each handle fully in, through where the wall is; from the first moment it is out
    homed = np.flatnonzero(follower > WALL_Z + 0.005)[0]
    follower, hand, wall = follower[homed:], hand[homed:], wall[homed:]
    touching = np.flatnonzero(wall > 0)
    assert touching.size > 1500
    # the hand's 3 N (at most the coupling's 8 N) against 2000 N/m: a few millimetres into the wall, no more
    assert follower.min() > WALL_Z - 0.004
    held = touching[hand[touching] == -PUSH]
    assert np.median(follower[held]) == pytest.approx(WALL_Z - PUSH / STIFFNESS, abs=0.5e-3)


def test_the_walls_force_is_the_scenes_spring_and_damper_on_the_depth(pushed):
    *_, fx, fy, fz, z, vz = pushed.T
    depth, approach = WALL_Z - z, -vz  # device z points to the operator, away from the wall
    expected = np.where(depth > 0, np.maximum(STIFFNESS * depth + DAMPING * approach, 0.0), 0.0)
    assert (expected > 1.0).sum() > 1000
    # (homing pushes the handle through the wall: the scene's force is then far above what touch lets through)
    assert np.abs(fz - expected).max() < 1e-3
    assert np.abs(fx).max() < 1e-6 and np.abs(fy).max() < 1e-6  # a frictionless tip on a wall facing +z


def test_in_free_space_the_hand_feels_about_nothing(pushed):
    leader, follower, hand, felt, wall, *_ = pushed.T
    free = np.flatnonzero((follower > WALL_Z + 0.005) & (wall == 0))
    free = free[free > 300]  # after the follower's homing hand has placed it
    assert free.size > 1000
    # moving, the hand feels only the follower's inertia and the coupling's damping: a fraction of the wall's push
    assert np.abs(felt[free]).max() < 0.25 * PUSH
    assert np.abs(felt[free][hand[free] == 0]).max() < 0.2  # nothing at all at rest
