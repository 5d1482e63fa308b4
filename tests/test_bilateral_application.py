"""systems/bilateral.yaml: two simulated Falcons coupled position-position, under the virtual clock through
their real frame codec. The leader's hand feels the follower's wall, and nothing in free space."""

import numpy as np
import pytest

from hapticop.composition.lcsm import State
from hapticop.runtime.system import ExitStatus

from .conftest import SYSTEMS
from .runtime_helpers import compose, step_thread

WALL_Z, PUSH = -0.02, 3.0  # systems/bilateral.yaml's follower wall and the leader's hand's push


def test_the_bilateral_set_up_runs_from_yaml_alone_and_ends_with_its_script(tmp_path):
    result = compose(tmp_path, (SYSTEMS / "bilateral.yaml").read_text(), duration="20s", name="bilateral")
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert all(state is State.DONE for state in result.states.values())
    assert "the script is over" in (tmp_path / "run-bilateral" / "hand.log").read_text()


@pytest.fixture(scope="module")
def pushed(tmp_path_factory):
    """Per cycle once both Falcons run: leader and follower true z, the hand's z force, the leader's felt z force."""
    def sample(b):
        return (b["leader_sim"].outputs.handle_position.value[2], b["follower_sim"].outputs.handle_position.value[2],
                b["hand"].outputs.hand_force.value[2], b["coupling"].outputs.leader_force.value[2],
                b["wall"].outputs.force.value[2])
    rows = step_thread(tmp_path_factory.mktemp("bilateral"), SYSTEMS / "bilateral.yaml", 6000, sample,
                       gate="follower")
    return np.array(rows)


def test_the_leaders_hand_feels_the_followers_wall(pushed):
    leader, follower, hand, felt, wall = pushed.T
    holding = np.flatnonzero(hand == -PUSH)
    assert holding.size > 1500  # the hand held 3 N towards the wall for two seconds
    settled = holding[holding > holding[0] + 500]
    assert (follower[settled] < WALL_Z).all() and (wall[settled] > 0).all()  # the follower is in the wall
    assert (leader[settled] < follower[settled]).all()  # the leader went further: the coupling is stretched
    assert (felt[settled] > 0.8 * PUSH).all()  # and pushes the hand back, towards the operator, nearly its push
    assert np.median(felt[settled]) == pytest.approx(PUSH, rel=0.1)  # at rest the hand's push is all met by the wall


def test_in_free_space_the_hand_feels_about_nothing(pushed):
    leader, follower, hand, felt, wall = pushed.T
    free = np.flatnonzero((follower > WALL_Z + 0.005) & (wall == 0))
    free = free[free > 300]  # after the follower's homing hand has placed it
    assert free.size > 1000
    # moving, the hand feels only the follower's inertia and the coupling's damping: a fraction of the wall's push
    assert np.abs(felt[free]).max() < 0.25 * PUSH
    assert np.abs(felt[free][hand[free] == 0]).max() < 0.2  # nothing at all at rest
