"""A scene that breaks stops the run with one message that says where: MuJoCo cannot load it (validation
refuses it, the run never starts), or it explodes while running (a body flies off; the state goes to NaN,
which MuJoCo answers by resetting the simulation). Never a trace."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from hapticop.runtime.system import ExitStatus
from hapticop.sim.engine import Engine, SceneError
from hapticop.sim.scene import Movable, Scene, to_mjcf

from .conftest import SYSTEMS
from .runtime_helpers import compose

# The bilateral desk with a feather (a micro-gram board) between the follower's handle and the wall, and a handle
# a million times stiffer than the Falcon's tip and as light as the feather: homing presses the handle into the
# feather, which the contact throws out of the scene within a second.
FEATHER_SCENE = """walls:
  - {name: wall, size_m: [0.1, 0.6, 0.6], position_m: [0.075, 0.0]}
bodies:
  - {name: feather, size_m: [0.01, 0.1, 0.6], position_m: [0.015, 0.0], mass_kg: 0.000001}
handles:
  - {name: follower, origin_m: [0.0, 0.0, 0.3], axes: [-y, z, -x], stiffness_n_per_m: 1000000.0, mass_kg: 0.000001}
robot: {start: [-2.0, 0.0, 0.0]}
"""

ON_THE_FEATHER = f"""extends: {SYSTEMS / "bilateral.yaml"}
name: feather
activities:
  world:
    params: {{scene: feather_desk.yaml}}
"""


def _logs(run_dir) -> str:
    return "\n".join(path.read_text() for path in sorted(run_dir.glob("*.log")))


def test_a_scene_that_throws_a_body_out_stops_the_run_with_one_message_at_the_body(tmp_path):
    (tmp_path / "feather_desk.yaml").write_text(FEATHER_SCENE)
    result = compose(tmp_path, ON_THE_FEATHER, duration="30s", name="feather")
    assert result.outcome.status is ExitStatus.FAILURE
    # the world's failure; the rest is what its stop cut short (the leader, homed later, never ran)
    assert result.outcome.reasons[0] == "'world' failed (running failed)", result.outcome.reasons
    assert all("never reached running" in reason for reason in result.outcome.reasons[1:])
    # stopped by the world's explosion, long before the duration (and before the script's end at 5 s)
    assert result.timing["activities"]["mediator"]["steps"] < 5000
    logs = _logs(tmp_path / "run-feather")
    assert "Traceback" not in logs
    [said] = [line for line in logs.splitlines() if "exploded" in line]
    assert f"{tmp_path / 'feather_desk.yaml'}:4: bodies.0 'feather': " in said and "'bodies[0]' left the scene" in said


def _unstable_mjcf(gravity: str) -> str:
    """A scene whose gravity throws its crate (MJCF: the scene file for anything richer)."""
    xml = to_mjcf(Scene(bodies=(Movable(name="crate", size_m=(0.2, 0.2, 0.2), position_m=(3.0, 0.0), mass_kg=1.0),)))
    return xml.replace('integrator="implicitfast"/>', f'integrator="implicitfast" gravity="{gravity}"/>')


ALONE = """version: 1
name: alone
threads:
  sim:
    period: 1ms
    deploy: main
    schedules: {0: [mediator, world]}
activities:
  mediator: {block: mediator}
  world:
    block: scene_world
    params: {scene: CRATE, judge: false, plot: false}
coordination:
  nets:
    run:
      places: {START: , RUNNING: , BROKEN: , STOP: , STOPPED: }
      marking: {START: 1}
      terminal: [STOPPED]
      transitions:
        begin: {in: [START], out: [RUNNING]}
        broke: {in: [RUNNING, BROKEN], out: [STOP, STOPPED]}
  flag_maps:
    run:
      net: run
      converting_sources: {world.finished: BROKEN}
      converting_sinks: {system.stop: STOP}
"""


@pytest.mark.parametrize("gravity, said", [("0 0 1e9", "left the scene"),  # a body flies off
                                           ("0 0 1e300", "not a number, infinite or huge")])  # MuJoCo resets
def test_an_mjcf_scene_that_explodes_stops_the_run_with_one_message_naming_file_and_body(tmp_path, gravity, said):
    crate = "crate.xml"  # each case's own folder: a relative path is read beside the composition run
    (tmp_path / crate).write_text(_unstable_mjcf(gravity))
    result = compose(tmp_path, ALONE.replace("CRATE", crate), duration="30s", name="alone")
    assert result.outcome.status is ExitStatus.FAILURE
    assert result.timing["activities"]["mediator"]["steps"] < 1000
    logs = _logs(tmp_path / "run-alone")
    assert "Traceback" not in logs
    [line] = [line for line in logs.splitlines() if said in line]
    assert f"{tmp_path / crate}: bodies[0]: " in line and "exploded" in line


def test_mujoco_resetting_an_unstable_simulation_is_an_explosion_not_a_silent_restart():
    engine = Engine(_unstable_mjcf("0 0 1e300"))
    with pytest.raises(SceneError, match="body 'bodies\\[0\\]' went to a value not a number") as raised:
        for _ in range(10):
            engine.step()
    assert raised.value.body == "bodies[0]"


def test_a_body_flying_straight_up_has_left_the_scene():
    engine = Engine(_unstable_mjcf("0 0 1e9"))
    with pytest.raises(SceneError, match="left the scene"):
        for _ in range(10):
            engine.step()
    assert np.isfinite(engine.qpos).all()  # it flew: no NaN needed to notice


def test_a_scene_mujoco_cannot_load_is_refused_by_compose_in_one_located_line(tmp_path):
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><geom type='box' size='1'/></worldbody></mujoco>")
    (tmp_path / "alone.yaml").write_text(ALONE.replace("CRATE", "broken.xml"))
    run = subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(tmp_path / "alone.yaml"), "--clock",
                          "virtual", "--duration", "1s"], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    output = run.stdout + run.stderr
    assert run.returncode != 0 and "Traceback" not in output
    [line] = [line for line in output.splitlines() if "MuJoCo cannot load" in line]
    assert line.startswith(f"{tmp_path / 'broken.xml'}") and "MuJoCo cannot load the scene" in line
