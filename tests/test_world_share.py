"""A simulator finds its world's geometry by the world activity's name, in any process of the run."""

from __future__ import annotations

import subprocess
import sys

from hapticop.sim.hallway import HallwayGeometry
from hapticop.sim.world_share import find_world, publish_world, withdraw_world


def test_a_simulator_finds_the_world_it_is_told_about(tmp_path):
    assert find_world(tmp_path, "world") is None
    publish_world(tmp_path, "world", HallwayGeometry.named("H4"))
    assert find_world(tmp_path, "world") == HallwayGeometry.named("H4")
    assert find_world(tmp_path, "other_world") is None
    withdraw_world(tmp_path, "world")
    assert find_world(tmp_path, "world") is None


def test_a_simulator_in_another_process_finds_it(tmp_path):
    publish_world(tmp_path, "world", HallwayGeometry.named("H3"))
    found = subprocess.run([sys.executable, "-c", "import sys; from hapticop.sim.world_share import find_world; "
                            "print(find_world(sys.argv[1], 'world').name)", str(tmp_path)],
                           capture_output=True, text=True, check=True)
    assert found.stdout.strip() == "H3"
