"""The Foxglove layout shipped for the hallway (foxglove-layouts/hallway.json), built with the SDK.

The 3D panel follows the robot (base_link) with the scan and the force arrow (`scene`); beside it,
plots of the handle's position, the environment force and the commanded twist, from the raw
stream channels against the loops' own stamps (publish time). Regenerate the file with
`python -m hapticop.recording.layout > foxglove-layouts/hallway.json`.
"""

from __future__ import annotations

import json

from hapticop.recording.mcapfile import topic_of
from hapticop.recording.scene import ARROW_TOPIC, BASE, SCAN_TOPIC

PLOTS = (  # (title, stream, a label per element)
    ("Handle position (m)", "handle_position", ("x (right)", "y (up)", "z (towards the operator)")),
    ("Environment force (N)", "environment_force", ("x", "y", "z")),
    ("Commanded velocity (m/s, rad/s)", "velocity_setpoint", ("vx", "vy", "wz")),
)


def hallway_layout() -> str:
    """The layout as Foxglove's JSON."""
    import foxglove.layouts as fl

    def plot(title: str, stream: str, labels: tuple[str, ...]):
        return fl.PlotPanel(title=title, config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=f"{topic_of(stream)}.data[{i}]", label=label, enabled=True,
                                 timestamp_method="publishTime") for i, label in enumerate(labels)],
            show_legend=True, legend_display="floating", x_axis_val="timestamp", following_view_width=10))

    scene = fl.ThreeDeePanel(title="Hallway", config=fl.ThreeDeeConfig(
        follow_tf=BASE, follow_mode="follow-position",
        topics={SCAN_TOPIC: fl.BaseRendererLaserScanTopicSettings(visible=True, point_size=4, color_mode="flat",
                                                                  flat_color="#2ca02c"),
                ARROW_TOPIC: fl.BaseRendererSceneUpdateTopicSettings(visible=True)}))
    layout = fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=scene),
        fl.SplitItem(proportion=2, content=fl.SplitContainer(direction="column", items=[
            fl.SplitItem(content=plot(*row)) for row in PLOTS])),
    ]))
    return json.dumps(json.loads(layout.to_json()), indent=2) + "\n"


if __name__ == "__main__":
    print(hallway_layout(), end="")
