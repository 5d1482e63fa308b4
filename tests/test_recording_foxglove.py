"""A recorded hallway run carries what Foxglove shows: the scan, the REP-105 frames and the force
arrow, each decoded here with the protobuf descriptor Foxglove's own SDK ships."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from hapticop.recording.layout import hallway_layout
from hapticop.recording.reading import series
from hapticop.recording.scene import ARROW_TOPIC, FRAMES_TOPIC, SCAN_TOPIC, arrow

from .conftest import ROOT
from .runtime_helpers import compose

messages = pytest.importorskip("foxglove.messages")


def _decoder(kind: str):
    """The message class built from the SDK's FileDescriptorSet, nothing of ours."""
    schema = getattr(messages, kind).get_schema()
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def _decoded(path, topic, kind):
    decode = _decoder(kind)
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        found = [(schema.name, m.sequence, m.publish_time, decode.FromString(m.data))
                 for schema, _, m in reader.iter_messages(topics=[topic])]
    assert found and {name for name, *_ in found} == {f"foxglove.{kind}"}
    return found


@pytest.fixture(scope="module")
def hallway_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hallway")
    text = (ROOT / "systems" / "hallway.yaml").read_text() + "\nrecord: {}\n"
    compose(tmp, text, duration="2s", name="hallway")
    return tmp / "run-hallway" / "hallway.mcap"


def test_the_scan_decodes_with_foxgloves_schema_one_message_per_scan(hallway_run):
    scans = _decoded(hallway_run, SCAN_TOPIC, "LaserScan")
    ranges, angles = series(hallway_run, "scan_ranges"), series(hallway_run, "scan_angles")
    assert len(scans) == len(ranges.sequence) > 0
    assert len(angles.sequence) == len(scans)
    for (_, _, publish, scan), recorded, stamp, beams in zip(
            scans, ranges.values, ranges.publish_ns, angles.values, strict=True):
        assert scan.frame_id == "laser" and len(scan.ranges) == 811
        assert np.array_equal(scan.ranges, recorded.astype(np.float64), equal_nan=True)  # NaN: no echo
        assert publish == stamp and scan.timestamp.seconds * 10**9 + scan.timestamp.nanos == stamp
        assert math.isclose(scan.start_angle, beams[0], abs_tol=1e-6)  # the scanner looks ahead: no heading
        assert math.isclose(scan.end_angle, beams[-1], abs_tol=1e-6)
        assert math.isclose(scan.start_angle, math.radians(-135.0), abs_tol=1e-5)
        # Foxglove spreads the ranges evenly from start to end: so are the beams
        assert np.allclose(np.linspace(scan.start_angle, scan.end_angle, len(beams)), beams, atol=1e-6)
    assert any(np.isfinite(scan.ranges).any() for _, _, _, scan in scans)  # the hallway's walls were seen
    assert [sequence for _, sequence, _, _ in scans] == list(range(1, len(scans) + 1))


def test_the_frames_chain_map_odom_base_link_laser_from_the_robots_pose(hallway_run):
    frames = _decoded(hallway_run, FRAMES_TOPIC, "FrameTransforms")
    pose = series(hallway_run, "pose_in_hallway")
    for _, _, publish, message in frames:
        chain = [(t.parent_frame_id, t.child_frame_id) for t in message.transforms]
        assert chain == [("map", "odom"), ("odom", "base_link"), ("base_link", "laser")]
        laser = message.transforms[2].translation
        assert (laser.x, laser.y) == (0.25, 0.0)  # the TiM561's mount on the ropod
    publish_times = [publish for _, _, publish, _ in frames]
    assert np.all(np.diff(publish_times) > 0)
    assert set(publish_times) <= set(pose.publish_ns.tolist())
    # odom is where the robot started; map -> odom -> base_link is the pose it was recorded at
    start = pose.values[0]
    last = frames[-1][3].transforms
    k = int(np.searchsorted(pose.publish_ns, publish_times[-1]))
    x, y, theta = pose.values[k]
    odom, moved = last[0], last[1]
    assert (odom.translation.x, odom.translation.y) == pytest.approx((start[0], start[1]))
    c, s = math.cos(start[2]), math.sin(start[2])
    assert (odom.translation.x + c * moved.translation.x - s * moved.translation.y,
            odom.translation.y + s * moved.translation.x + c * moved.translation.y) == pytest.approx((x, y))
    heading = 2 * math.atan2(odom.rotation.z, odom.rotation.w) + 2 * math.atan2(moved.rotation.z, moved.rotation.w)
    assert math.remainder(heading - theta, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_the_handle_force_is_an_arrow_over_the_robot(hallway_run):
    arrows = _decoded(hallway_run, ARROW_TOPIC, "SceneUpdate")
    force = series(hallway_run, "handle_force")
    assert 0 < len(arrows) <= len(force.sequence)
    for _, _, publish, update in arrows:
        (entity,) = update.entities
        assert entity.frame_id == "base_link" and len(entity.arrows) == 1
        k = int(np.searchsorted(force.publish_ns, publish))
        assert force.publish_ns[k] == publish
        fx, fy, fz = force.values[k]
        shape = entity.arrows[0]
        assert shape.shaft_length + shape.head_length == pytest.approx(0.05 * math.sqrt(fx * fx + fy * fy + fz * fz))


def test_an_arrow_points_along_its_force():
    decode = _decoder("SceneUpdate")
    for force in [(1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, -3.0), (-4.0, 0.0, 0.0), (1.0, 1.0, 1.0)]:
        q = decode.FromString(arrow(*force, 0).encode()).entities[0].arrows[0].pose.orientation
        # +x turned by q: the first column of its rotation matrix
        direction = (1 - 2 * (q.y * q.y + q.z * q.z), 2 * (q.x * q.y + q.z * q.w), 2 * (q.x * q.z - q.y * q.w))
        assert direction == pytest.approx(np.array(force) / np.linalg.norm(force), abs=1e-9)


def _panels(content):
    if content["type"] == "panel":
        yield content
    for item in content.get("items", []):
        yield from _panels(item["content"])


def test_the_shipped_layout_is_the_built_one_and_names_channels_the_recording_has(hallway_run):
    shipped = (ROOT / "foxglove-layouts" / "hallway.json").read_text()
    assert shipped == hallway_layout()  # regenerate: python -m hapticop.recording.layout
    with open(hallway_run, "rb") as stream:
        topics = {channel.topic for channel in make_reader(stream).get_summary().channels.values()}
    panels = list(_panels(json.loads(shipped)["content"]))
    (scene,) = [p["config"] for p in panels if p["panelType"] == "ThreeDee"]
    assert scene["followTf"] == "base_link" and {SCAN_TOPIC, ARROW_TOPIC} <= set(scene["topics"]) <= topics
    plotted = {path["value"].split(".")[0] for p in panels if p["panelType"] == "Plot" for path in p["config"]["paths"]}
    assert plotted == {"/streams/handle_position", "/streams/environment_force", "/streams/velocity_setpoint",
                       "/timing/main", "/timing/fieldbus", "/timing/watchdog"}
    assert plotted <= topics
    (log,) = [p["config"] for p in panels if p["panelType"] == "Log"]
    assert log["topicToRender"] in topics
    (states,) = [p["config"] for p in panels if p["panelType"] == "StateTransitions"]
    shown = {path["value"].split("{")[0].split(".")[0] for path in states["paths"]}
    assert shown == {"/events/lifecycle", "/events/mode"}
    assert shown - {"/events/mode"} <= topics  # the hallway switches no mode: its channel comes with the first
    with open(hallway_run, "rb") as stream:
        owners = {json.loads(m.data)["owner"] for _, _, m in make_reader(stream).iter_messages(
            topics=["/events/lifecycle"])}
    labelled = {path["label"] for path in states["paths"]} - {"modes"}
    assert labelled <= owners  # every life cycle the layout shows is one the hallway's recording has
