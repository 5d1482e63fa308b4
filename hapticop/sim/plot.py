"""A one-page PNG of a run: the path from above (in the hallway, or among a scene's static geometry), then
force and velocity over time.

Why: a glance at a run shows what the metrics summarise (where it drifted, how it stopped, how the cue felt).
matplotlib is optional (the `report` extra) and imported only here, inside the function.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hapticop.devices.ropod.body import Footprint
from hapticop.sim.recording import TrajectoryRecorder, as_channels

if TYPE_CHECKING:
    from hapticop.sim.hallway_task import Hallway


def scene_outlines(engine, grow_m: float = 0.0) -> list[np.ndarray]:
    """Each static geom of a loaded scene (hapticop.sim.engine) seen from above: a box's four corners, any
    other shape a circle of its radius; (k, 2) arrays of x, y, in the order of `engine.static`. `grow_m`
    widens each by that much on every side (a distance drawn around it)."""
    import mujoco

    m, d = engine.model, engine.data
    mujoco.mj_kinematics(m, d)
    outlines = []
    for g in engine.static:
        centre, size = d.geom_xpos[g, :2], m.geom_size[g]
        if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            turn = d.geom_xmat[g].reshape(3, 3)[:2, :2]
            local = np.array([(1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0)]) * (size[:2] + grow_m)
            outlines.append(centre + local @ turn.T)
        else:
            a = np.linspace(0.0, 2.0 * np.pi, 33)
            outlines.append(centre + (size[0] + grow_m) * np.column_stack([np.cos(a), np.sin(a)]))
    return outlines


def plot_run(
    data: TrajectoryRecorder | Mapping[str, np.ndarray],
    geometry: Hallway | None,
    path: str | Path,
    *,
    walls: Sequence[np.ndarray] = (),
    footprint: Footprint | None = None,
    title: str | None = None,
    footprint_every_s: float = 1.0,
    dpi: int = 110,
) -> Path:
    """Write the PNG and return its path. Needs the "t" and "pose" channels; forces and velocities if logged.
    In a hallway its scene's static geometry is drawn, with dist1 around the sides and dist2 before the end
    wall; without one (`geometry` None) the path is drawn among `walls` (`scene_outlines`)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RuntimeError("plotting a run needs matplotlib: pip install 'hapticop[report]'") from exc

    d = as_channels(data)
    t, pose = d["t"], d["pose"]
    g = geometry
    fig = Figure(figsize=(11, 8.5), layout="constrained")
    FigureCanvasAgg(fig)  # Agg, without pyplot: no global state, no display needed
    top, mid, low = fig.subplots(3, 1, height_ratios=[1.4, 1, 1])

    # Top view: the scene's static geometry, dist1 around its sides, dist2 before its end wall, the path.
    if g is not None:
        engine = g.engine()
        walls = scene_outlines(engine)
        for grow, front, style, label in (
                (g.dist1_m, False, dict(ls=":", color="tab:green"), "dist1 from the sides"),
                (g.dist2_m, True, dict(ls="--", color="tab:red"), "dist2 before the end wall")):
            for i, outline in enumerate(scene_outlines(engine, grow)):
                if g.front[i] == front:
                    closed = np.vstack([outline, outline[:1]])
                    top.plot(closed[:, 0], closed[:, 1], lw=1, label=label, **style)
                    label = None
    for outline in walls:
        top.fill(outline[:, 0], outline[:, 1], facecolor="0.3", edgecolor="black", lw=0.8)
    fp = g.footprint if g is not None else footprint or Footprint()
    reach = np.vstack([*walls, pose[:, :2]]) if len(walls) else pose[:, :2]
    every = max(1, int(round(footprint_every_s / max(float(np.median(np.diff(t))), 1e-9)))) if len(t) > 1 else 1
    for c in fp.corners(pose[::every]):
        top.fill(c[:, 0], c[:, 1], facecolor="tab:blue", alpha=0.08, edgecolor="tab:blue", lw=0.5)
    c = fp.corners(pose[-1])
    top.fill(c[:, 0], c[:, 1], facecolor="none", edgecolor="tab:blue", lw=1.5)
    top.plot(pose[:, 0], pose[:, 1], color="tab:blue", lw=1.2, label="robot centre")
    top.set_aspect("equal")
    top.set_xlim(float(reach[:, 0].min()) - 0.3, float(reach[:, 0].max()) + 0.3)  # not the grown outlines
    top.set_ylim(float(reach[:, 1].min()) - 0.3, float(reach[:, 1].max()) + 0.3)
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m] (left +)")
    top.set_title(title or f"{g.name if g is not None else 'scene'}: run of {t[-1] - t[0]:.1f} s")
    top.legend(loc="upper left", fontsize=8)

    if "force_env" in d:
        f = d["force_env"]
        mid.plot(t, f[:, 0], lw=0.8, label="F_env x")
        mid.plot(t, f[:, 2], lw=0.8, label="F_env z")
        mid.plot(t, np.linalg.norm(f, axis=1), lw=1.0, color="black", label="|F_env|")
    if "force_hand" in d:
        mid.plot(t, d["force_hand"][:, 2], lw=0.8, alpha=0.6, label="F_hand z")
    mid.set_ylabel("force [N]")
    mid.grid(alpha=0.3)
    if mid.lines:
        mid.legend(loc="upper right", fontsize=8, ncol=4)

    # Linear and angular velocity have axes of their own (m/s left, rad/s right), one colour per source.
    spin = low.twinx()
    for (key, label), colour in zip((("cmd", "cmd"), ("cmd_exec", "exec"), ("robot_velocity", "robot")),
                                    ("tab:blue", "tab:orange", "tab:green")):
        if key in d:
            low.plot(t, d[key][:, 0], lw=0.9, color=colour, label=f"v {label}")
            spin.plot(t, d[key][:, 1], lw=0.7, ls="--", color=colour, label=f"omega {label}")
    low.set_xlabel("t [s]")
    low.set_ylabel("linear v [m/s] (solid)")
    spin.set_ylabel("angular omega [rad/s] (dashed)")
    low.grid(alpha=0.3)
    if low.lines:
        low.legend(low.lines + spin.lines, [line.get_label() for line in low.lines + spin.lines],
                   loc="upper right", fontsize=8, ncol=3)

    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path
