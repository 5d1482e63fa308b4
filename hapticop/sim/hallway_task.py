"""The hallway experiment's task as its metrics measure it: the constants of a scene's `hallway:` section,
and the robot's clearances to the scene's end wall and sides, from MuJoCo on the scene's own model.

Why: one world. The scanner's rays, the collisions and the metrics' clearances are all MuJoCo's answers
about the same compiled scene (hapticop.sim.engine), so a hallway is data (hapticop/sim/scenes/) and
nothing measures a second, hand-written copy of its walls. The world records the clearances each cycle
as it measures them; `clearances` computes them again for a log that lacks them (a run rebuilt from a
recording's streams, a synthetic run in a test).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from hapticop.devices.ropod.body import Footprint
from hapticop.sim.engine import Engine
from hapticop.sim.judge import STILL_MPS, STILL_S
from hapticop.sim.scene import Scene


@dataclass(frozen=True)
class Hallway:
    """A scene with a hallway task: its name, compiled scene, which static geoms are the end wall, the
    robot's start and footprint, and §2's task distances and end-of-run rules."""

    name: str
    xml: str
    front: tuple[bool, ...]  # per static geom of the engine (`Engine.static`): the end wall
    start: tuple[float, float, float]  # x, y [m], theta [rad]
    footprint: Footprint
    middle_x_m: float  # a standstill ends the run only past here
    dist1_m: float = 0.40
    dist2_m: float = 0.50
    dist3_m: float = 0.10
    collision_hysteresis_m: float = 0.02
    t_max_s: float = 90.0
    still_speed_mps: float = STILL_MPS  # the world's end-of-run rule, as the metrics evaluate it on the log
    still_time_s: float = STILL_S

    @classmethod
    def of(cls, scene: Scene, xml: str) -> Hallway:
        """The task of a scene with a `hallway:` section (ValueError without one)."""
        task = scene.hallway
        if task is None:
            raise ValueError("the scene has no 'hallway' task")
        named = set(task.end_wall)
        ends = {mjcf for mjcf, (kind, i) in scene.static_names()
                if mjcf in named or getattr(scene, kind)[i].name in named}
        r = scene.robot
        return cls(name=task.name, xml=xml, front=tuple(n in ends for n in _engine(xml).static_names),
                   start=(r.start[0], r.start[1], math.radians(r.start[2])),
                   footprint=Footprint(length_m=r.length_m, width_m=r.width_m), middle_x_m=task.middle_x_m,
                   dist1_m=task.dist1_m, dist2_m=task.dist2_m, dist3_m=task.dist3_m)

    @classmethod
    def named(cls, ref: str, folder: Path | None = None) -> Hallway:
        """The task of a scene file: a shipped hallway (H1..H6) or a file beside `folder`."""
        from hapticop.sim import scene_files

        loaded, found = scene_files.load(ref, folder)
        if loaded is None:
            raise ValueError("; ".join(d.to_text() for d in found))
        if loaded.scene is None or loaded.scene.hallway is None:
            raise ValueError(f"scene {ref!r} has no 'hallway' task")
        return cls.of(loaded.scene, loaded.xml)

    def engine(self) -> Engine:
        """The scene loaded in MuJoCo (one per scene and process, for measuring logs after the run)."""
        return _engine(self.xml)

    def clearances(self, poses: np.ndarray) -> np.ndarray:
        """(n, 3): the footprint's least clearance to all static geometry, to the end wall and to the sides,
        with the robot at each pose (x, y, theta); 0 or less: touching or inside."""
        return self.engine().trajectory_clearances(poses, self.front)


@lru_cache(maxsize=8)
def _engine(xml: str) -> Engine:
    return Engine(xml)
