"""What a simulated world shares with the simulators that live in it, found by its activity's name.

The world's scene (its compiled MJCF, the LIDAR's model) is fixed for a run, so the world writes it
once into the run directory, where a simulator in any process of the run finds it by the world
activity's name (the name its `world:` parameter gives, which validation checks). Everything that
moves (the robot's pose, the operator's hand) travels in declared streams instead. The same way,
the operator says who it is (its variant), which the world's judge needs for the run's targets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from hapticop.published import publish, published, withdraw

if TYPE_CHECKING:
    from hapticop.sim.scene import Scene


@dataclass(frozen=True)
class PublishedScene:
    """What a scene world tells the simulators in it: the compiled scene and the LIDAR's model."""

    xml: str
    start: tuple[float, float, float]
    noise_sigma_m: float
    min_range_m: float
    max_range_m: float
    yaw_rad: float

    @classmethod
    def of(cls, scene: Scene, xml: str) -> PublishedScene:
        """A scene's share: its compiled MJCF, the robot's start and the LIDAR's model (angles in radians)."""
        start, lidar = scene.robot.start, scene.robot.lidar
        return cls(xml, (start[0], start[1], math.radians(start[2])), lidar.noise_sigma_m, lidar.min_range_m,
                   lidar.max_range_m, math.radians(lidar.yaw_deg))


def publish_world(run_dir: Path, activity: str, scene: PublishedScene) -> None:
    """Write the world's scene where its simulators look."""
    publish(run_dir, "worlds", activity, scene)


def find_world(run_dir: Path, activity: str) -> PublishedScene | None:
    """The scene of the world `activity`, or None until it is open (a world left behind by an
    ended run in a reused run directory does not count)."""
    return published(run_dir, "worlds", activity, as_type=PublishedScene)


def withdraw_world(run_dir: Path, activity: str) -> None:
    withdraw(run_dir, "worlds", activity)


def publish_operator(run_dir: Path, activity: str, description: dict) -> None:
    """Say who the operator `activity` is (its variant, its seed)."""
    publish(run_dir, "operators", activity, description)


def find_operator(run_dir: Path, activity: str) -> dict | None:
    """What the operator `activity` said about itself this run, or None if it said nothing (read
    when the run is judged, perhaps after the operator's process has ended)."""
    return published(run_dir, "operators", activity, while_writer_lives=False)
