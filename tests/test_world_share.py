"""A simulator finds its world's geometry by the world activity's name, in any process of the run."""

from __future__ import annotations

import subprocess
import sys

from hapticop.sim import scene_files
from hapticop.sim.world_share import PublishedScene, find_world, publish_world, withdraw_world


def shipped(name: str) -> PublishedScene:
    loaded, _ = scene_files.load(name)
    return PublishedScene.of(loaded.scene, loaded.xml)


def test_a_simulator_finds_the_world_it_is_told_about(tmp_path):
    assert find_world(tmp_path, "world") is None
    publish_world(tmp_path, "world", shipped("H4"))
    assert find_world(tmp_path, "world") == shipped("H4")
    assert find_world(tmp_path, "other_world") is None
    withdraw_world(tmp_path, "world")
    assert find_world(tmp_path, "world") is None


def test_a_simulator_in_another_process_finds_it(tmp_path):
    publish_world(tmp_path, "world", shipped("H3"))
    found = subprocess.run([sys.executable, "-c", "import sys; from hapticop.sim.world_share import find_world; "
                            "print(find_world(sys.argv[1], 'world').xml)", str(tmp_path)],
                           capture_output=True, text=True, check=True)
    assert found.stdout.strip() == shipped("H3").xml.strip()
