"""A scene: the simulated world as data (floor, walls, boxes, cylinders, movable bodies, the robot and
its LIDAR), compiled to MuJoCo's MJCF.

Why: a user writes a room, a corridor or an obstacle in YAML instead of Python, and one physics engine
(MuJoCo) answers every question the simulation asks of it: where the scanner's beams end, what the robot
touches, how a pushed box moves. The model here is only the description and its compilation; the loaded
engine is `hapticop.sim.engine`, the located checks `hapticop.sim.scene_files`.

Frames are the hallway's (REP 103): x forward, y left, z up, yaw counter-clockwise; positions in metres,
angles in degrees where a person writes them. Sizes are full lengths (MJCF's are halves).
"""

from __future__ import annotations

import math
from typing import Literal
from xml.sax.saxutils import quoteattr

from pydantic import BaseModel, ConfigDict, Field, field_validator

from hapticop.devices.ropod.body import Body
from hapticop.sim.judge import Target

_ROBOT = Body()


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)



class Material(_Strict):
    """How a surface grips and looks."""

    friction: float = Field(0.8, ge=0, description="sliding friction coefficient (MuJoCo's, against the other "
                            "surface's: the larger of the two holds)")
    rgba: tuple[float, float, float, float] = Field((0.7, 0.7, 0.7, 1.0), description="colour, 0..1 each")


MATERIALS: dict[str, Material] = {
    "floor": Material(friction=0.6, rgba=(0.55, 0.55, 0.5, 1.0)),
    "wall": Material(friction=0.8, rgba=(0.85, 0.85, 0.8, 1.0)),
    "wood": Material(friction=0.45, rgba=(0.6, 0.45, 0.3, 1.0)),
    "cardboard": Material(friction=0.5, rgba=(0.75, 0.6, 0.4, 1.0)),
    "metal": Material(friction=0.3, rgba=(0.6, 0.62, 0.65, 1.0)),
    "rubber": Material(friction=1.0, rgba=(0.15, 0.15, 0.15, 1.0)),
}
"""Materials every scene knows; a scene's own `materials:` add to them or replace one by name."""


class Floor(_Strict):
    """The floor everything stands on."""

    material: str = Field("floor", description="a material of MATERIALS or of the scene's `materials`")


class Block3(_Strict):
    """A static box standing on the floor: a wall, a pillar, a shelf."""

    name: str = Field("", description="what it is called in messages and in the compiled MJCF")
    size_m: tuple[float, float, float] = Field(description="full length along x, y and height (m), before its yaw")
    position_m: tuple[float, float] | tuple[float, float, float] = Field(
        description="its centre x, y (m); a third value is the centre's height, else it stands on the floor")
    yaw_deg: float = Field(0.0, description="turned counter-clockwise about z")
    material: str = Field("wall", description="a material of MATERIALS or of the scene's `materials`")


class Cylinder(_Strict):
    """A static upright cylinder standing on the floor: a column, a post."""

    name: str = Field("", description="what it is called in messages")
    radius_m: float = Field(gt=0, description="its radius (m)")
    height_m: float = Field(gt=0, description="its height (m)")
    position_m: tuple[float, float] = Field(description="its axis' x, y (m)")
    material: str = Field("wall", description="a material of MATERIALS or of the scene's `materials`")


class Movable(_Strict):
    """A body that moves when pushed: it slides on the floor with its friction and damping."""

    name: str = Field("", description="what it is called in messages")
    shape: Literal["box", "cylinder"] = Field("box", description="its shape")
    size_m: tuple[float, float, float] | None = Field(None, description="a box's full lengths x, y, z (m)")
    radius_m: float | None = Field(None, gt=0, description="a cylinder's radius (m)")
    height_m: float | None = Field(None, gt=0, description="a cylinder's height (m)")
    position_m: tuple[float, float] = Field(description="its centre x, y (m) on the floor")
    yaw_deg: float = Field(0.0, description="turned counter-clockwise about z")
    mass_kg: float | None = Field(None, description="its mass: a movable body needs one (> 0)")
    material: str = Field("cardboard", description="a material of MATERIALS or of the scene's `materials`")
    friction: float | None = Field(None, ge=0, description="its sliding friction, if not its material's")
    damping_ns_per_m: float = Field(0.0, ge=0, description="viscous damping of its sliding (N s/m) and turning")


class Lidar(_Strict):
    """Where the scanner sits on the robot and what it sees (the TiM561: docs/devices/sick-tim561.md)."""

    x_m: float = Field(_ROBOT.lidar.x_m, description="ahead of the robot's centre")
    y_m: float = Field(_ROBOT.lidar.y_m, description="left of the robot's centre")
    height_m: float = Field(0.20, gt=0, description="above the floor (thesis §4.3.3: 20 cm)")
    yaw_deg: float = Field(math.degrees(_ROBOT.lidar.yaw_rad), description="its heading on the robot")
    noise_sigma_m: float = Field(0.01, ge=0, description="Gaussian range noise (standard deviation)")
    min_range_m: float = Field(0.05, gt=0, description="nearer returns count as none")
    max_range_m: float = Field(10.0, gt=0, description="farther returns count as none")


AXES = ("x", "y", "z")


class Handle(_Strict):
    """A device's handle as a body of the scene: a sphere put, every step, where the device's position says,
    which touches the scene's walls and bodies. The contacts' force on it is published in the device's
    frame, so a haptic device (a Falcon) can feel the scene. The contact is a spring and damper on the
    depth: F = stiffness * depth + damping * approach speed (MuJoCo's soft contact, set to these values)."""

    name: str = Field(pattern=r"^[a-z][a-z0-9_]*$", max_length=40, description="its ports on the world are "
                      "NAME_handle_position, NAME_handle_velocity (in) and NAME_handle_force (out)")
    origin_m: tuple[float, float, float] = Field(description="where the device frame's origin is in the scene (m)")
    axes: tuple[str, str, str] = Field(("x", "y", "z"), description="the device's x, y and z axes as scene axes "
                                       "('x', '-y', ...): a Falcon (x right, y up, z towards its operator) facing "
                                       "the scene's +x is [-y, z, -x]")
    radius_m: float = Field(0.005, gt=0, le=0.5, description="the sphere's radius: the tip that touches (m)")
    mass_kg: float = Field(0.1, gt=0, description="its mass as bodies it pushes feel it")
    stiffness_n_per_m: float = Field(2000.0, gt=0, le=1e6, description="the contact's stiffness on the depth")
    damping_ns_per_m: float = Field(2.0, ge=0, le=1e4, description="the contact's damping on the approach speed")
    friction: float = Field(0.0, ge=0, description="sliding friction of the tip (0: frictionless; with friction "
                            "the normal force departs from the equation by a few per cent, MuJoCo's pyramidal cone)")

    @field_validator("axes")
    @classmethod
    def _a_rotation(cls, axes: tuple[str, str, str]) -> tuple[str, str, str]:
        """A right-handed frame: each scene axis once, with the handedness of x, y, z."""
        for a in axes:
            if a.lstrip("+-") not in AXES or a.count("-") + a.count("+") > 1:
                raise ValueError(f"axis {a!r} is none of x, y, z, -x, -y, -z")
        if sorted(a.lstrip("+-") for a in axes) != list(AXES):
            raise ValueError(f"{list(axes)} names a scene axis twice: each of x, y, z once")
        if round(float(_det(handle_rotation(axes)))) != 1:
            raise ValueError(f"{list(axes)} is a left-handed frame: change one sign")
        return axes


def handle_rotation(axes: tuple[str, str, str]) -> list[list[float]]:
    """The device's axes as columns of scene vectors: R with p_scene = origin + R p_device."""
    columns = []
    for a in axes:
        v = [0.0, 0.0, 0.0]
        v[AXES.index(a.lstrip("+-"))] = -1.0 if a.startswith("-") else 1.0
        columns.append(v)
    return columns


def _det(c: list[list[float]]) -> float:
    (a, b, x), (d, e, y), (g, h, z) = c
    return a * (e * z - y * h) - d * (b * z - x * h) + g * (b * y - x * e)


class Robot(_Strict):
    """The ropod: a rigid rectangular base moved by the plant (hapticop.devices.ropod.plant)."""

    start: tuple[float, float, float] = Field((0.5, 0.0, 0.0), description="x, y (m) and heading (deg) where it starts")
    length_m: float = Field(_ROBOT.footprint.length_m, gt=0, description="footprint along x")
    width_m: float = Field(_ROBOT.footprint.width_m, gt=0, description="footprint along y")
    height_m: float = Field(0.15, gt=0, description="its body's height; it rides 5 mm above the floor")
    mass_kg: float = Field(36.5, gt=0, description="the plant's mass (thesis §4.3.2)")
    yaw_inertia_kgm2: float = Field(2.6, gt=0, description="the plant's I_z")
    lidar: Lidar = Field(default_factory=Lidar, description="the scanner on it")


class HallwayTask(_Strict):
    """What the hallway experiment's metrics measure against (docs/hallway-experiment.md §2, §5): the
    clearances themselves are MuJoCo's, from the robot's geom to the scene's static geometry."""

    name: str = Field(description="H1..H6 of docs/hallway-experiment.md §2, or a name of the user's own")
    end_wall: tuple[str, ...] = Field(("end",), min_length=1, description="the static geometry (names of walls, "
                                      "boxes or cylinders) the stop is measured against; all the rest is the sides")
    middle_x_m: float = Field(description="a standstill ends the run only past this x (the hallway's middle)")
    dist1_m: float = Field(0.40, description="side clearance to keep")
    dist2_m: float = Field(0.50, description="where the front should stop before the end wall")
    dist3_m: float = Field(0.10, description="virtual bumper: nearer counts as a collision")


class Scene(_Strict):
    """A whole scene. Static geometry may touch but not overlap; the robot starts clear of it."""

    doc: str = Field("", description="what the scene is, in words")
    materials: dict[str, Material] = Field(default_factory=dict, description="materials of its own, by name")
    floor: Floor = Field(default_factory=Floor, description="an endless plane at z = 0")
    walls: tuple[Block3, ...] = Field((), description="static boxes (default material 'wall')")
    boxes: tuple[Block3, ...] = Field((), description="more static boxes: pillars, shelves")
    cylinders: tuple[Cylinder, ...] = Field((), description="static upright cylinders")
    bodies: tuple[Movable, ...] = Field((), description="movable bodies")
    handles: tuple[Handle, ...] = Field((), description="devices' handles in the scene, each moved by its device")
    robot: Robot = Field(default_factory=Robot, description="the ropod: its start, body and LIDAR")
    hallway: HallwayTask | None = Field(None, description="the hallway experiment's task, for its metrics")
    targets: tuple[Target, ...] | str = Field((), description="task targets a run in the scene is judged by "
                                              "(docs/scenes.md, the judge), or a file of them beside the scene "
                                              "('hallway': the hallway experiment's, shipped)")
    timestep_s: float = Field(0.001, gt=0, le=0.01, description="the engine's step: the simulators' period")

    def material(self, name: str) -> Material | None:
        return self.materials.get(name) or MATERIALS.get(name)

    def static_names(self) -> list[tuple[str, tuple]]:
        """Every static geom's MJCF name and the YAML path it comes from."""
        named = [(f"walls[{i}]", ("walls", i)) for i in range(len(self.walls))]
        named += [(f"boxes[{i}]", ("boxes", i)) for i in range(len(self.boxes))]
        return named + [(f"cylinders[{i}]", ("cylinders", i)) for i in range(len(self.cylinders))]


ROBOT_JOINTS = ("robot_x", "robot_y", "robot_yaw")
"""The robot body's planar joints; an MJCF file named instead of a scene must have them, its body
`robot` with one geom `robot`, and a site `lidar` on it."""
_GAP_M = 0.005  # the robot's base rides this far above the floor: it touches walls and bodies, not the floor


def _f(*values: float) -> str:
    return " ".join(repr(float(v)) for v in values)


def _geom_attrs(scene: Scene, material: str, friction: float | None = None) -> str:
    m = scene.material(material) or Material()
    return f'friction="{_f(m.friction if friction is None else friction, 0.005, 0.0001)}" rgba="{_f(*m.rgba)}"'


def to_mjcf(scene: Scene, name: str = "scene") -> str:
    """The scene as MJCF text (MuJoCo's XML), every geom named after the YAML entry it comes from."""
    out = [f"<mujoco model={quoteattr(name)}>",
           f'  <option timestep="{_f(scene.timestep_s)}" integrator="implicitfast"/>',
           "  <worldbody>",
           f'    <geom name="floor" type="plane" size="0 0 0.1" {_geom_attrs(scene, scene.floor.material)}/>']
    for kind, items in (("walls", scene.walls), ("boxes", scene.boxes)):
        for i, b in enumerate(items):
            z = b.position_m[2] if len(b.position_m) == 3 else 0.5 * b.size_m[2]
            out.append(f'    <geom name="{kind}[{i}]" type="box" size="{_f(*(0.5 * s for s in b.size_m))}" '
                       f'pos="{_f(b.position_m[0], b.position_m[1], z)}" euler="0 0 {_f(b.yaw_deg)}" '
                       f'{_geom_attrs(scene, b.material)}/>')
    for i, c in enumerate(scene.cylinders):
        out.append(f'    <geom name="cylinders[{i}]" type="cylinder" size="{_f(c.radius_m, 0.5 * c.height_m)}" '
                   f'pos="{_f(*c.position_m, 0.5 * c.height_m)}" {_geom_attrs(scene, c.material)}/>')
    r = scene.robot
    hz = 0.5 * r.height_m
    out += ['    <body name="robot" pos="0 0 0">',
            f'      <joint name="robot_x" type="slide" axis="1 0 0" pos="0 0 {_f(_GAP_M + hz)}"/>',
            '      <joint name="robot_y" type="slide" axis="0 1 0"/>',
            '      <joint name="robot_yaw" type="hinge" axis="0 0 1"/>',
            f'      <inertial pos="0 0 {_f(_GAP_M + hz)}" mass="{_f(r.mass_kg)}" '
            f'diaginertia="{_f(r.yaw_inertia_kgm2, r.yaw_inertia_kgm2, r.yaw_inertia_kgm2)}"/>',
            f'      <geom name="robot" type="box" size="{_f(0.5 * r.length_m, 0.5 * r.width_m, hz)}" '
            f'pos="0 0 {_f(_GAP_M + hz)}" contype="2" conaffinity="1" rgba="0.2 0.4 0.8 1" '
            'friction="0.3 0.005 0.0001"/>',
            f'      <site name="lidar" pos="{_f(r.lidar.x_m, r.lidar.y_m, r.lidar.height_m)}"/>',
            "    </body>"]
    for i, b in enumerate(scene.bodies):
        if b.shape == "box":
            sx, sy, sz = b.size_m or (0.1, 0.1, 0.1)
            z, size, kind = 0.5 * sz, _f(0.5 * sx, 0.5 * sy, 0.5 * sz), "box"
        else:
            z, size, kind = 0.5 * (b.height_m or 0.1), _f(b.radius_m or 0.05, 0.5 * (b.height_m or 0.1)), "cylinder"
        out += [f'    <body name="bodies[{i}]" pos="{_f(b.position_m[0], b.position_m[1], z)}" '
                f'euler="0 0 {_f(b.yaw_deg)}">',
                f'      <joint name="bodies[{i}]" type="free" damping="{_f(b.damping_ns_per_m)}"/>',
                f'      <geom name="bodies[{i}]" type="{kind}" size="{size}" mass="{_f(b.mass_kg or 1.0)}" '
                f'{_geom_attrs(scene, b.material, b.friction)}/>',
                "    </body>"]
    for h in scene.handles:
        out += _handle_mjcf(h)
    out += ["  </worldbody>", "</mujoco>"]
    return "\n".join(out) + "\n"


HANDLE_SOLIMP = 0.99
"""The handle's contact impedance, constant over depth: with stiffness and damping given directly
(negative solref), MuJoCo's contact force on a body of mass m is then m (k depth + b speed)."""


def _handle_mjcf(h: Handle) -> list[str]:
    """A handle: a sphere on three slide joints along the device's axes from its origin, so the joints'
    positions are the device's and their constraint force is the contact force in the device frame. Its
    weight compensated (gravcomp); its contact parameters win over the other geom's (priority)."""
    n, m = f"handle_{h.name}", h.mass_kg
    joints = [f'      <joint name="{n}_{a}" type="slide" axis="{_f(*column)}"/>'
              for a, column in zip(AXES, handle_rotation(h.axes), strict=True)]
    condim = 3 if h.friction > 0 else 1
    return ([f'    <body name="{n}" pos="{_f(*h.origin_m)}" gravcomp="1">'] + joints +
            [f'      <geom name="{n}" type="sphere" size="{_f(h.radius_m)}" mass="{_f(m)}" priority="1" '
             f'condim="{condim}" friction="{_f(h.friction, 0.005, 0.0001)}" '
             f'solref="{_f(-h.stiffness_n_per_m / m, -h.damping_ns_per_m / m)}" '
             f'solimp="{_f(HANDLE_SOLIMP, HANDLE_SOLIMP, 0.001)}" rgba="0.9 0.3 0.2 1"/>',
             "    </body>"])
