"""A scene loaded in MuJoCo: the robot placed where its plant says, one physics step, what the robot
touches, how far it is from the static geometry, and a LIDAR scan by ray casting.

Why one class: the world and the simulated scanner each load the same compiled scene in their own
process and ask it different questions; the buffers every question needs are made once here, so a
1 kHz step and a 15 Hz scan allocate no arrays.

The robot's motion is the ropod plant's (its wheels, its dynamics): each step the robot's planar joints
are put where the plant's pose is, moving at its twist; MuJoCo then resolves the contacts of that step
and moves the other bodies. The constraint force the contacts put on the robot's joints is what the
plant gets back: pushing a box slows it, a wall stops it.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from hapticop.sim.scene import ROBOT_JOINTS

FAR_M = 1e3
"""A body farther than this from the origin has flown off: the run stops (a numerical explosion)."""


class SceneError(RuntimeError):
    """The engine found the scene broken while running (NaN state, a body flown off); `body` is the MJCF name of
    the body it blames ("" when none), for the world to say where the scene declares it."""

    def __init__(self, message: str, body: str = ""):
        super().__init__(message)
        self.body = body


_UNSTABLE = (int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQVEL),
             int(mujoco.mjtWarning.mjWARN_BADQACC))
"""MuJoCo's warnings that it found NaN, infinite or huge values in the state and reset the simulation."""


class Engine:
    """One scene's MjModel and MjData, with the robot's joints and the movable bodies found by name."""

    def __init__(self, xml: str, name: str = "scene"):
        self.name = name
        self.model = m = mujoco.MjModel.from_xml_string(xml)
        self.data = d = mujoco.MjData(m)
        missing = [j for j in ROBOT_JOINTS if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) < 0]
        self.robot_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "robot")
        self.robot_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "robot")
        self.lidar_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "lidar")
        if missing or min(self.robot_body, self.robot_geom, self.lidar_site) < 0:
            lacking = f" (missing joints: {', '.join(missing)})" if missing else ""
            raise ValueError("the scene needs a body 'robot' with the joints robot_x, robot_y, robot_yaw, one geom "
                             f"'robot' and a site 'lidar'{lacking}")
        joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in ROBOT_JOINTS]
        self.qpos_robot = [int(m.jnt_qposadr[j]) for j in joints]
        self.dof_robot = [int(m.jnt_dofadr[j]) for j in joints]
        self.lidar_offset = m.site_pos[self.lidar_site].copy()  # in the robot body's frame
        # static geoms: on the world body, except the floor (a plane the robot rides above)
        self.static = np.array([g for g in range(m.ngeom) if m.geom_bodyid[g] == 0 and m.geom_type[g] !=
                                mujoco.mjtGeom.mjGEOM_PLANE], dtype=np.int32)
        self.static_ids = [int(g) for g in self.static]
        self.static_names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, int(g)) or f"geom {g}" for g in self.static]
        # movable bodies: those with a free joint; their poses as x, y, yaw
        free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        self.body_qpos = [int(m.jnt_qposadr[j]) for j in free]
        self.body_names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.jnt_bodyid[j])) or f"body {j}"
                           for j in free]
        self.handles, self.handle_qpos, self.handle_dofs = _handles(m)
        # views and buffers made once
        self.qpos, self.qvel = d.qpos, d.qvel
        self.qfrc_constraint = d.qfrc_constraint
        self._warned, self._warned_at = d.warning.number, d.warning.lastinfo  # live views of MuJoCo's counters
        self._fromto = np.zeros(6)
        self._rays: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._origin = np.zeros(3)
        mujoco.mj_forward(m, d)

    @property
    def bodies(self) -> int:
        return len(self.body_qpos)

    def place_robot(self, pose: np.ndarray, twist: np.ndarray | None = None) -> None:
        """The robot where its plant is (x, y, theta in the scene) moving at its twist (vx, vy in its own
        frame, wz)."""
        qpos, (ix, iy, it) = self.qpos, self.qpos_robot
        theta = float(pose[2])
        qpos[ix], qpos[iy], qpos[it] = float(pose[0]), float(pose[1]), theta
        qvel, (vx_, vy_, wz_) = self.qvel, self.dof_robot
        if twist is None:
            qvel[vx_] = qvel[vy_] = qvel[wz_] = 0.0
            return
        c, s = math.cos(theta), math.sin(theta)
        vx, vy = float(twist[0]), float(twist[1])
        qvel[vx_], qvel[vy_], qvel[wz_] = c * vx - s * vy, s * vx + c * vy, float(twist[2])

    def step(self) -> None:
        """One physics step of `timestep`; a state gone non-finite (MuJoCo resets it and counts a warning) or
        a body flown off stops the run."""
        mujoco.mj_step(self.model, self.data)
        warned = self._warned
        for kind in _UNSTABLE:
            if warned[kind]:
                self._unstable(kind)
        qpos = self.qpos
        for i, adr in enumerate(self.body_qpos):
            x, y, z = qpos[adr], qpos[adr + 1], qpos[adr + 2]
            if not (abs(x) < FAR_M and abs(y) < FAR_M and abs(z) < FAR_M):  # also false for NaN
                name = self.body_names[i]
                raise SceneError(f"scene '{self.name}': body '{name}' left the scene or its state is not a number "
                                 f"(x={x:.3g}, y={y:.3g}, z={z:.3g}): the simulation exploded; look at its mass, "
                                 "size and damping, or the robot's speed", name)

    def _unstable(self, kind: int) -> None:
        m = self.model
        dof = int(self._warned_at[kind])
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.dof_bodyid[dof])) if 0 <= dof < m.nv else None
        what = {"QPOS": "position", "QVEL": "velocity", "QACC": "acceleration"}[
            mujoco.mjtWarning(kind).name.removeprefix("mjWARN_BAD")]
        blamed = f"body '{body}'" if body else f"degree of freedom {dof}"
        raise SceneError(f"scene '{self.name}': {blamed} went to a value not a number, infinite or huge (its {what}) "
                         f"at {self.data.time:.3f} s of simulation: the simulation exploded (MuJoCo reset it); look at "
                         "its mass, size, damping and the forces on it", body or "")

    def place_handle(self, i: int, position: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Handle i where its device is (its joints are the device's axes: the device's own coordinates)."""
        qpos, qvel = self.qpos, self.qvel
        for k, adr in enumerate(self.handle_qpos[i]):
            qpos[adr] = position[k]
        for k, adr in enumerate(self.handle_dofs[i]):
            qvel[adr] = 0.0 if velocity is None else velocity[k]

    def handle_force(self, i: int, out: np.ndarray) -> np.ndarray:
        """The contacts' force on handle i in the last step, in its device's frame (N)."""
        f = self.qfrc_constraint
        for k, adr in enumerate(self.handle_dofs[i]):
            out[k] = f[adr]
        return out

    def contact_wrench(self, out: np.ndarray) -> np.ndarray:
        """The contacts' force and torque on the robot in the last step, in the robot's frame (N, N, N m)."""
        f, (ix, iy, it) = self.qfrc_constraint, self.dof_robot
        theta = float(self.qpos[self.qpos_robot[2]])
        c, s = math.cos(theta), math.sin(theta)
        fx, fy = float(f[ix]), float(f[iy])
        out[0], out[1], out[2] = c * fx + s * fy, -s * fx + c * fy, float(f[it])
        return out

    def clearance(self, reach_m: float = FAR_M) -> float:
        """The smallest distance from the robot's geom to static geometry at its current placement
        (0 or less: touching or inside); `reach_m` when nothing is nearer."""
        return self.clearances(None, reach_m)[0]

    def clearances(self, front: tuple[bool, ...] | None, reach_m: float = FAR_M) -> tuple[float, float, float]:
        """The robot's least distance (as `clearance`) to all static geometry, to the static geoms marked in
        `front` (one flag per geom of `static`) and to the others: a hallway's end wall and its sides."""
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        best = ahead = beside = reach_m
        robot = self.robot_geom
        for i, g in enumerate(self.static_ids):
            dist = mujoco.mj_geomDistance(m, d, robot, g, reach_m, None)
            if dist < best:
                best = dist
            if front is not None and front[i]:
                if dist < ahead:
                    ahead = dist
            elif dist < beside:
                beside = dist
        return best, ahead, beside

    def trajectory_clearances(self, poses: np.ndarray, front: tuple[bool, ...] | None,
                              reach_m: float = FAR_M) -> np.ndarray:
        """`clearances` with the robot at each of `poses` (n, 3) in turn: (n, 3) of all, front, side; for a
        run's log after the run (the world records them as it goes)."""
        out = np.empty((len(poses), 3))
        for i, pose in enumerate(np.asarray(poses, dtype=np.float64)):
            self.place_robot(pose)
            out[i] = self.clearances(front, reach_m)
        return out

    def body_poses(self, out: np.ndarray) -> np.ndarray:
        """Each movable body's x, y and yaw (rows of out)."""
        qpos = self.qpos
        for i, adr in enumerate(self.body_qpos):
            w, x, y, z = qpos[adr + 3], qpos[adr + 4], qpos[adr + 5], qpos[adr + 6]
            out[i, 0], out[i, 1] = qpos[adr], qpos[adr + 1]
            out[i, 2] = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return out

    def place_bodies(self, poses: np.ndarray) -> None:
        """Movable bodies where another process's engine says they are (x, y, yaw; upright)."""
        qpos = self.qpos
        for i, adr in enumerate(self.body_qpos):
            qpos[adr], qpos[adr + 1] = poses[i, 0], poses[i, 1]
            half = 0.5 * float(poses[i, 2])
            qpos[adr + 3], qpos[adr + 4], qpos[adr + 5], qpos[adr + 6] = math.cos(half), 0.0, 0.0, math.sin(half)

    def scan(self, angles: np.ndarray, out: np.ndarray, min_range_m: float, max_range_m: float,
             yaw_rad: float = 0.0) -> np.ndarray:
        """Ranges along beams at `angles` (the sensor's frame) from the LIDAR site, horizontal, at the
        robot's current placement; NaN where nothing lies within [min_range_m, max_range_m]."""
        m, d = self.model, self.data
        n = angles.shape[0]
        buffers = self._rays.get(n)
        if buffers is None:
            buffers = self._rays[n] = (np.zeros(3 * n), np.zeros(n, np.int32), np.zeros(n), np.zeros(n, bool))
        vec, geomid, dist, mask = buffers
        mujoco.mj_kinematics(m, d)
        theta = float(self.qpos[self.qpos_robot[2]]) + yaw_rad
        np.copyto(self._origin, d.site_xpos[self.lidar_site])
        directions = vec.reshape(n, 3)
        np.add(angles, theta, out=dist)
        np.cos(dist, out=directions[:, 0])
        np.sin(dist, out=directions[:, 1])
        mujoco.mj_multiRay(m, d, self._origin, vec, None, 1, self.robot_body, geomid, dist, None, n, max_range_m)
        np.less(geomid, 0, out=mask)  # no hit: dist is -1
        np.copyto(dist, np.nan, where=mask)
        np.less(dist, min_range_m, out=mask)
        np.copyto(dist, np.nan, where=mask)
        np.greater(dist, max_range_m, out=mask)
        np.copyto(dist, np.nan, where=mask)
        np.copyto(out, dist, casting="same_kind")
        return out


def _handles(m) -> tuple[list[str], list[list[int]], list[list[int]]]:
    """The scene's handles: bodies `handle_NAME` with the slide joints `handle_NAME_x`, `_y`, `_z`
    (hapticop.sim.scene.Handle compiles to them; an MJCF file may have its own)."""
    names, qpos, dofs = [], [], []
    for b in range(m.nbody):
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if not body.startswith("handle_"):
            continue
        joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{body}_{a}") for a in "xyz"]
        if min(joints) < 0 or any(m.jnt_type[j] != mujoco.mjtJoint.mjJNT_SLIDE or m.jnt_bodyid[j] != b
                                  for j in joints):
            raise ValueError(f"body '{body}' is a handle by its name, but lacks its slide joints {body}_x, "
                             f"{body}_y and {body}_z")
        names.append(body.removeprefix("handle_"))
        qpos.append([int(m.jnt_qposadr[j]) for j in joints])
        dofs.append([int(m.jnt_dofadr[j]) for j in joints])
    return names, qpos, dofs
