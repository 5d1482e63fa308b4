"""The Foxglove layout shipped for the hallway (foxglove-layouts/hallway.json), built with the SDK.

The 3D panel follows the robot (base_link) with the scan and the force arrow (`scene`), the run's
log under it; beside them, plots of the handle's position, the environment force and the
commanded twist, from the raw stream channels against the loops' own stamps (publish time), and
the 1 kHz loops' worst wake-up latency per timing window (`/timing/THREAD`); under them, the
activities' life-cycle states and the modes that hold as state transitions, and the flags as
they change (`/events/KIND`). Regenerate the file with
`python -m hapticop.recording.layout > foxglove-layouts/hallway.json`.
"""

from __future__ import annotations

import json

from hapticop.recording.mcapfile import EVENT_TOPIC, LOG_TOPIC, TIMING_TOPIC, topic_of
from hapticop.recording.scene import ARROW_TOPIC, BASE, SCAN_TOPIC

PLOTS = (  # (title, stream, a label per element)
    ("Handle position (m)", "handle_position", ("x (right)", "y (up)", "z (towards the operator)")),
    ("Environment force (N)", "environment_force", ("x", "y", "z")),
    ("Commanded velocity (m/s, rad/s)", "velocity_setpoint", ("vx", "vy", "wz")),
)
LOOPS = ("main", "fieldbus", "watchdog")  # the hallway's 1 kHz threads
OWNERS = ("mediator", "falcon", "lidar", "ropod", "ethercat", "haptic")  # the hallway's activities on the robot's path


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
    timing = fl.PlotPanel(title="Wake-up latency, worst per timing window (us)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"{TIMING_TOPIC.format(loop)}.latency_max_us", label=loop, enabled=True,
                             timestamp_method="publishTime") for loop in LOOPS],
        show_legend=True, legend_display="floating", x_axis_val="timestamp", following_view_width=30))
    lifecycle = EVENT_TOPIC.format("lifecycle")
    states = fl.StateTransitionsPanel(title="Life cycles and modes", config=fl.StateTransitionsConfig(
        paths=[*(fl.StateTransitionsSeries(value=f'{lifecycle}{{owner=="{owner}"}}.state', label=owner, enabled=True,
                                           timestamp_method="publishTime") for owner in OWNERS),
               fl.StateTransitionsSeries(value=f"{EVENT_TOPIC.format('mode')}.modes", label="modes", enabled=True,
                                         timestamp_method="publishTime")],
        show_points=True, show_legend=True))
    flags = fl.RawMessagesPanel(title="Flags as they change", config=fl.RawMessagesConfig(
        topic_path=f"{EVENT_TOPIC.format('flags')}.changed", expansion="all"))
    log = fl.LogPanel(title="Log", config=fl.LogConfig(topic_to_render=LOG_TOPIC, show_name=True))
    layout = fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=fl.SplitContainer(direction="column", items=[
            fl.SplitItem(proportion=3, content=scene), fl.SplitItem(proportion=1, content=log),
            fl.SplitItem(proportion=1, content=fl.SplitContainer(direction="row", items=[
                fl.SplitItem(proportion=2, content=states), fl.SplitItem(proportion=1, content=flags)]))])),
        fl.SplitItem(proportion=2, content=fl.SplitContainer(direction="column", items=[
            *(fl.SplitItem(content=plot(*row)) for row in PLOTS), fl.SplitItem(content=timing)])),
    ]))
    return json.dumps(json.loads(layout.to_json()), indent=2) + "\n"


if __name__ == "__main__":
    print(hallway_layout(), end="")
