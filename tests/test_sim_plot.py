"""The run plot: a PNG from a log, matplotlib imported only when plotting."""

import subprocess
import sys

import numpy as np
import pytest

from hapticop.sim.hallway_task import Hallway
from hapticop.sim.plot import plot_run
from hapticop.sim.recording import TrajectoryRecorder

from .test_sim_metrics import straight_run


def test_importing_hapticop_sim_does_not_import_matplotlib():
    code = ("import sys, hapticop.sim.plot, hapticop.sim.recording, hapticop.sim.metrics, hapticop.sim.targets, "
            "hapticop.sim.operator; "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_clear_error_without_matplotlib(tmp_path, monkeypatch):
    for name in ("matplotlib", "matplotlib.figure", "matplotlib.backends.backend_agg"):
        monkeypatch.setitem(sys.modules, name, None)
    run, _ = straight_run()
    with pytest.raises(RuntimeError, match=r"pip install 'hapticop\[report\]'"):
        plot_run(run, Hallway.named("H1"), tmp_path / "run.png")


def test_the_plot_writes_a_png(tmp_path):
    g = Hallway.named("H4")
    y = lambda t: 0.2 * np.sin(t / 3)  # noqa: E731
    run, _ = straight_run(g=g, y=y)
    rec = TrajectoryRecorder(len(run["t"]), meta={"hallway": "H4"})
    for i, t in enumerate(run["t"]):
        rec.append(t, run["pose"][i], robot_velocity=run["robot_velocity"][i], cmd=run["robot_velocity"][i] * 1.1,
                   force_env=(0.1 * np.sin(t), 0.0, 0.05 * t))
    path = plot_run(rec, g, tmp_path / "run.png", title="H4 synthetic")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert plot_run(run, g, tmp_path / "pose_only.png").exists()


def test_linear_and_angular_velocity_have_axes_of_their_own(tmp_path, monkeypatch):
    """m/s and rad/s never share a scale: v on the left axis, omega on a twin axis on the right."""
    from matplotlib.figure import Figure

    drawn = []
    monkeypatch.setattr(Figure, "savefig", lambda self, *args, **kwargs: drawn.append(self))
    run, _ = straight_run(g=Hallway.named("H4"), y=lambda t: 0.2 * np.sin(t / 3))
    plot_run(run, Hallway.named("H4"), tmp_path / "run.png")
    (figure,) = drawn
    velocity = [axis for axis in figure.axes if "[m/s]" in axis.get_ylabel() or "[rad/s]" in axis.get_ylabel()]
    assert [axis.get_ylabel() for axis in velocity] == ["linear v [m/s] (solid)", "angular omega [rad/s] (dashed)"]
    linear, angular = velocity
    assert [line.get_label() for line in linear.lines] == ["v robot"]
    assert [line.get_label() for line in angular.lines] == ["omega robot"]
