"""A one-page PNG of a hallway run: the path in the hallway from above, then force and velocity over time.

Why: a glance at a run shows what the metrics summarise (where it drifted, how it stopped, how the cue felt).
matplotlib is optional (the `report` extra) and imported only here, inside the function.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from hapticop.sim.hallway import HallwayGeometry
from hapticop.sim.recording import TrajectoryRecorder, as_channels


def plot_run(
    data: TrajectoryRecorder | Mapping[str, np.ndarray],
    geometry: HallwayGeometry,
    path: str | Path,
    *,
    title: str | None = None,
    footprint_every_s: float = 1.0,
    dpi: int = 110,
) -> Path:
    """Write the PNG and return its path. Needs the "t" and "pose" channels; forces and velocities if logged."""
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

    # Top view: walls, comfort lines at dist1, the stop line at dist2, the path and footprints.
    segs, _ = g.segments()
    for s in segs:
        top.plot(s[:, 0], s[:, 1], color="black", lw=2.5, solid_capstyle="butt")
    h, inner = 0.5 * g.width_m, 0.5 * g.width_m - g.dist1_m
    for y, label in ((inner, "dist1 from the side walls"), (-inner, None)):
        top.plot([g.entrance_x_m, g.length_m], [y, y], ls=":", color="tab:green", lw=1, label=label)
    top.plot([g.stop_line_x_m] * 2, [-h, h], ls="--", color="tab:red", lw=1, label="dist2 stop line")
    every = max(1, int(round(footprint_every_s / max(float(np.median(np.diff(t))), 1e-9)))) if len(t) > 1 else 1
    for c in g.footprint.corners(pose[::every]):
        top.fill(c[:, 0], c[:, 1], facecolor="tab:blue", alpha=0.08, edgecolor="tab:blue", lw=0.5)
    c = g.footprint.corners(pose[-1])
    top.fill(c[:, 0], c[:, 1], facecolor="none", edgecolor="tab:blue", lw=1.5)
    top.plot(pose[:, 0], pose[:, 1], color="tab:blue", lw=1.2, label="robot centre")
    top.set_aspect("equal")
    top.set_xlim(min(g.entrance_x_m, float(pose[:, 0].min())) - 0.3, g.length_m + 0.3)
    top.set_ylim(-h - 0.3, h + 0.3)
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m] (left +)")
    top.set_title(title or f"{g.name}: run of {t[-1] - t[0]:.1f} s")
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
