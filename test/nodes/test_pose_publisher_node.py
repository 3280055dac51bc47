"""Pose publisher node and summary message conversion (in-process, private rclpy context)."""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from awalker_tracker.inference.gait_events import Step
from awalker_tracker.inference.posterior import LEFT, RIGHT, WALKER_FIELDS, FootContactEstimate, MarkerCloud, PosteriorSummary
from awalker_tracker.model.body import JOINT_NAMES, MARKER_NAMES, BodyDescription


def make_summary(stamp_ns: int, frame: int, rng, contacts=None, left_probability: float = 0.2) -> PosteriorSummary:
    markers = rng.normal(size=(13, 3)) + [0, 0, 1]
    return PosteriorSummary(
        frame_index=frame, stamp_ns=stamp_ns, marker_names=MARKER_NAMES, joint_names=JOINT_NAMES,
        map_markers=markers, mean_markers=markers + 0.01, map_joint_angles=rng.normal(size=len(JOINT_NAMES)),
        map_torso_position=markers[0], map_torso_orientation=np.array([0, 0, np.sin(0.2), np.cos(0.2)]),
        map_stance_leg=RIGHT, map_walker={k: float(i) for i, k in enumerate(WALKER_FIELDS)},
        speed=1.3, speed_std=0.1, stance_left_probability=left_probability, effective_sample_size=321.0,
        num_particles=500,
        resampled=True,
        contacts=contacts if contacts is not None else (
            FootContactEstimate(LEFT, np.array([0.1, 0.2, 0.0]), 0.2, False),
            FootContactEstimate(RIGHT, np.array([0.4, 0.0, 0.0]), 0.8, True)),
        clouds=(MarkerCloud("head", rng.normal(size=(20, 3)), rng.random(20) / 20),))


def test_summary_message_roundtrip():
    from awalker_tracker.nodes.messages import summary_from_msg, summary_to_msg

    s = make_summary(1_700_000_000_123_456_789, 4, np.random.default_rng(0))
    msg = summary_to_msg(s, "world")
    assert msg.header.stamp.sec == 1_700_000_000 and msg.header.stamp.nanosec == 123_456_789
    back = summary_from_msg(msg)
    assert back.stamp_ns == s.stamp_ns and back.frame_index == 4 and back.marker_names == MARKER_NAMES
    assert np.allclose(back.map_markers, s.map_markers) and np.allclose(back.mean_markers, s.mean_markers)
    assert np.allclose(back.map_joint_angles, s.map_joint_angles) and back.joint_names == JOINT_NAMES
    assert np.allclose(back.map_torso_orientation, s.map_torso_orientation)
    assert back.map_walker == s.map_walker and back.map_stance_leg == RIGHT
    assert back.contacts[1].heel_strike and np.allclose(back.contacts[0].position, [0.1, 0.2, 0])
    assert np.allclose(back.clouds[0].weights, s.clouds[0].weights, atol=1e-7)
    assert back.clouds[0].points.shape == (20, 3) and np.allclose(back.clouds[0].points, s.clouds[0].points, atol=1e-6)
    assert back.speed == 1.3 and back.resampled and back.effective_sample_size == 321.0
    assert not back.legs_renamed
    assert summary_from_msg(summary_to_msg(replace(s, legs_renamed=True), "world")).legs_renamed
    assert back.steps == ()
    carried = (gait_step(0, 3, "right", float("nan")), gait_step(1, 4, "left", 0.7))
    steps = summary_from_msg(summary_to_msg(replace(s, steps=carried), "world")).steps
    assert [(t.index, t.frame, t.stamp_ns, t.foot, t.x, t.step_length_m) for t in steps[1:]] == [
        (c.index, c.frame, c.stamp_ns, c.foot, c.x, c.step_length_m) for c in carried[1:]]
    assert [t.time_s for t in steps] == pytest.approx([c.time_s for c in carried], abs=1e-9)


def test_cylinder_geometry():
    from awalker_tracker.nodes.messages import summary_to_msg
    from awalker_tracker.nodes.pose_publisher_node import MarkerBuilder, body_cylinders, quaternion_z_to

    for d in ([0, 0, 1], [1, 0, 0], [0.3, -0.4, 0.5], [0, 0, -1]):
        q = np.array(quaternion_z_to(np.array(d, float)))
        x, y, z, w = q
        rot_z = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
        assert np.allclose(rot_z, np.array(d) / np.linalg.norm(d))
    s = make_summary(10, 0, np.random.default_rng(1))
    body = BodyDescription.default()
    array = MarkerBuilder(body_cylinders(body)).build(summary_to_msg(s))
    cyl = [m for m in array.markers if m.ns.endswith("/body")]
    assert len(cyl) == 8
    knee, ankle = s.map_markers[MARKER_NAMES.index("left_knee")], s.map_markers[MARKER_NAMES.index("left_ankle")]
    shin = [m for m in cyl if np.isclose(m.scale.z, np.linalg.norm(ankle - knee))]
    assert len(shin) == 1
    assert np.allclose([shin[0].pose.position.x, shin[0].pose.position.y, shin[0].pose.position.z], (knee + ankle) / 2)
    assert not [m for m in array.markers if "cloud" in m.ns]         # the clouds go out as a PointCloud2
    assert all(m.header.stamp.nanosec == 10 for m in array.markers)


def test_a_reused_marker_builder_gives_the_markers_of_a_fresh_one():
    """The pose publisher keeps one MarkerBuilder and updates its messages: nothing of one frame may stay in the
    next (contacts appear, vanish and change between heel strike and stance). Compared field by field (the
    serialised bytes are not: CDR's padding bytes are left as they were in memory)."""
    from awalker_tracker.nodes.messages import summary_to_msg
    from awalker_tracker.nodes.pose_publisher_node import MarkerBuilder, body_cylinders

    rng = np.random.default_rng(5)
    cylinders = body_cylinders(BodyDescription.default())
    reused = MarkerBuilder(cylinders, "b7")
    kinds = [None, (FootContactEstimate(LEFT, np.array([0.3, 0.1, 0.0]), 0.6, False),
                    FootContactEstimate(RIGHT, np.full(3, np.nan), 0.0, False)),
             (FootContactEstimate(LEFT, np.full(3, np.nan), 0.0, False),
              FootContactEstimate(RIGHT, np.array([0.9, -0.1, 0.0]), 0.05, True))]
    counts = set()
    for frame in range(9):
        msg = summary_to_msg(make_summary(1000 + frame, frame, rng, kinds[frame % 3]))
        again = reused.build(msg)
        fresh = MarkerBuilder(cylinders, "b7").build(msg)
        assert again == fresh
        counts.add(len(again.markers))
        assert all(m.header.stamp.nanosec == 1000 + frame for m in again.markers)
    assert counts == {12}          # both contacts each frame: shown (ADD) or lifted (DELETE)


def test_a_foot_that_lifts_has_its_contact_marker_deleted():
    """In RViz both feet looked planted forever: a contact marker was only ever added. Now each frame sends
    each foot's contact as an ADD while it stands and a DELETE (same namespace and id) once it has lifted:
    no longer the posterior's stance foot with at least CONTACT_MIN_PROBABILITY, or no position."""
    from visualization_msgs.msg import Marker

    from awalker_tracker.nodes.messages import summary_to_msg
    from awalker_tracker.nodes.pose_publisher_node import CONTACT_MIN_PROBABILITY, MarkerBuilder, body_cylinders

    rng = np.random.default_rng(2)
    builder = MarkerBuilder(body_cylinders(BodyDescription.default()), "w")
    spot, nowhere = np.array([0.3, 0.1, 0.0]), np.full(3, np.nan)
    # (left probability, left position, right position) per frame: left stands, lifts, is barely likely
    frames = [(0.95, spot, spot + 0.6), (0.0, nowhere, spot + 0.6), (0.5 * CONTACT_MIN_PROBABILITY, spot, spot + 0.6),
              (0.6, spot + 1.2, spot + 0.6)]
    expected_left = [Marker.ADD, Marker.DELETE, Marker.DELETE, Marker.ADD]
    for k, ((p_left, left, right), action) in enumerate(zip(frames, expected_left)):
        contacts = (FootContactEstimate(LEFT, left, p_left, False), FootContactEstimate(RIGHT, right, 1 - p_left, False))
        markers = builder.build(summary_to_msg(make_summary(100 + k, k, rng, contacts))).markers
        dots = {m.id: m for m in markers if m.ns == "w/contacts"}
        assert set(dots) == {LEFT, RIGHT}
        assert dots[LEFT].action == action, k
        assert dots[RIGHT].action == (Marker.ADD if 1 - p_left >= CONTACT_MIN_PROBABILITY else Marker.DELETE), k
        assert dots[LEFT].header.stamp.nanosec == 100 + k
        if action == Marker.ADD:
            assert np.allclose([dots[LEFT].pose.position.x, dots[LEFT].pose.position.y], left[:2])


def test_particle_clouds_pack_into_a_pointcloud2_heaviest_first():
    from awalker_tracker.nodes.messages import PARTICLE_POINT, particles_to_pointcloud2, summary_to_msg

    rng = np.random.default_rng(3)
    s = replace(make_summary(10, 0, rng), clouds=(
        MarkerCloud("head", rng.normal(size=(20, 3)), rng.random(20) / 20),
        MarkerCloud("left_ankle", rng.normal(size=(30, 3)), rng.random(30) / 30)))
    msg = summary_to_msg(s)
    cloud = particles_to_pointcloud2(msg.header, msg.clouds, 8)
    assert cloud.header.stamp.nanosec == 10 and cloud.header.frame_id == "world"
    assert (cloud.height, cloud.width, cloud.point_step) == (1, 16, 20) and cloud.row_step == 16 * 20
    assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [
        ("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("weight", 12, 7), ("marker", 16, 6)]   # FLOAT32, UINT32
    points = np.frombuffer(bytes(cloud.data), PARTICLE_POINT)
    for index, source in enumerate(s.clouds):
        mine = points[points["marker"] == index]
        order = np.argsort(-source.weights, kind="stable")[:8]     # the 8 heaviest, heaviest first
        assert np.allclose(mine["weight"], source.weights[order], atol=1e-7)
        assert np.allclose(np.stack([mine["x"], mine["y"], mine["z"]], 1), source.points[order], atol=1e-6)
    everything = particles_to_pointcloud2(msg.header, msg.clouds, 1000)
    assert everything.width == 50 and len(everything.data) == 50 * 20
    assert particles_to_pointcloud2(msg.header, [], 8).width == 0


def _pose_publisher_outputs(ros_context, stamps: list[int], publisher_qos, seed: int) -> dict[str, list]:
    """One posterior per stamp, all published before a PosePublisherNode runs; its outputs by kind."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState, PointCloud2
    from visualization_msgs.msg import MarkerArray

    from awalker_msgs.msg import PosteriorSummary as SummaryMsg
    from awalker_tracker.nodes.messages import summary_to_msg
    from awalker_tracker.nodes.pose_publisher_node import PosePublisherNode

    node = PosePublisherNode(context=ros_context)
    probe = Node("probe", context=ros_context)
    got: dict[str, list] = {"joints": [], "rep155": [], "markers": [], "particles": []}
    qos = QoSProfile(depth=200)
    probe.create_subscription(JointState, "/awalker/joint_states", got["joints"].append, qos)
    probe.create_subscription(JointState, "/humans/bodies/walker/joint_states", got["rep155"].append, qos)
    probe.create_subscription(MarkerArray, "/awalker/markers", got["markers"].append, qos)
    probe.create_subscription(PointCloud2, "/awalker/particles", got["particles"].append, qos)
    pub = probe.create_publisher(SummaryMsg, "/awalker/posterior", publisher_qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)
    try:
        deadline = time.monotonic() + 5
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        rng = np.random.default_rng(seed)
        for k, stamp in enumerate(stamps):
            pub.publish(summary_to_msg(make_summary(stamp, k, rng)))
        while min(len(v) for v in got.values()) < len(stamps) and time.monotonic() < deadline + 10:
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
    return got


def test_node_publishes_joint_states_and_markers_with_image_stamp(ros_context):
    from rclpy.qos import QoSProfile

    from awalker_tracker.nodes.messages import stamp_to_ns

    stamps = [1_000_000_000 + k * 33_333_333 for k in range(5)]
    got = _pose_publisher_outputs(ros_context, stamps, QoSProfile(depth=50), seed=2)
    assert [stamp_to_ns(m.header.stamp) for m in got["joints"]] == stamps
    assert [stamp_to_ns(m.header.stamp) for m in got["rep155"]] == stamps
    assert [stamp_to_ns(m.markers[0].header.stamp) for m in got["markers"]] == stamps
    assert [stamp_to_ns(m.header.stamp) for m in got["particles"]] == stamps
    assert got["particles"][0].width == 20 and got["particles"][0].header.frame_id == "world"
    assert list(got["joints"][0].name) == list(JOINT_NAMES)
    assert all(m.header.frame_id == "world" for m in got["markers"][0].markers)


def test_a_burst_of_posteriors_is_published_whole(ros_context):
    """The automatic start publishes its window's posteriors at once (41 at 30 Hz, 80 at 60 Hz): the pose
    publisher answers every one. (With the queue depth of 10 it had, a hands-off track lost its first 15
    frames' joint states.)"""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from awalker_tracker.nodes.messages import POSTERIOR_DEPTH, stamp_to_ns

    stamps = [1_000_000_000 + k * 16_666_667 for k in range(80)]
    # the tracker's publisher (nodes.tracker_node): reliable, POSTERIOR_DEPTH
    got = _pose_publisher_outputs(ros_context, stamps, QoSProfile(depth=POSTERIOR_DEPTH,
                                  reliability=ReliabilityPolicy.RELIABLE), seed=3)
    assert [stamp_to_ns(m.header.stamp) for m in got["joints"]] == stamps
    assert [stamp_to_ns(m.markers[0].header.stamp) for m in got["markers"]] == stamps


def test_bad_body_description_is_reported(ros_context, tmp_path):
    from rclpy.parameter import Parameter

    from awalker_tracker.errors import InputError
    from awalker_tracker.nodes.pose_publisher_node import PosePublisherNode

    bad = tmp_path / "body.yaml"
    bad.write_text("body: {upper_leg_length: -1}\n")
    with pytest.raises(InputError, match="body.yaml"):
        PosePublisherNode(context=ros_context,
                          parameter_overrides=[Parameter("body_description", value=str(bad))])


def gait_step(index: int, frame: int, foot: str, length: float) -> Step:
    """A step struck 0.1 s before its frame (30 Hz stamps from 1 s), timed on the stamps' clock."""
    stamp = 1_000_000_000 + frame * 33_333_333
    return Step(index, frame, stamp, stamp * 1e-9 - 0.1, foot, 0.7 * index, 0.1, length, 0.2, 0.5, 1.0, 120.0, 1.4)


def test_the_summaries_steps_become_gait_steps(ros_context):
    """The steps the tracker's summaries carry (PosteriorSummary.steps, the MAP lineage's strikes at the step lag)
    come out on /awalker/gait_steps in order, each stamped with its strike frame's stamp, the strike itself, foot,
    heel and step values."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile

    from awalker_msgs.msg import GaitStep
    from awalker_msgs.msg import PosteriorSummary as SummaryMsg
    from awalker_tracker.nodes.messages import stamp_to_ns, summary_to_msg
    from awalker_tracker.nodes.pose_publisher_node import PosePublisherNode

    node = PosePublisherNode(context=ros_context, parameter_overrides=[])
    probe = Node("gait_probe", context=ros_context)
    got: list = []
    qos = QoSProfile(depth=100)
    probe.create_subscription(GaitStep, "/awalker/gait_steps", got.append, qos)
    pub = probe.create_publisher(SummaryMsg, "/awalker/posterior", qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)
    carried = {17: (gait_step(0, 2, "right", float("nan")),), 32: (gait_step(1, 17, "left", 0.7),),
               35: (gait_step(2, 20, "right", 0.65), gait_step(3, 35, "left", 0.7))}
    try:
        deadline = time.monotonic() + 5
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        rng = np.random.default_rng(4)
        for k in range(36):
            summary = replace(make_summary(1_000_000_000 + k * 33_333_333, k, rng), steps=carried.get(k, ()))
            pub.publish(summary_to_msg(summary))
            for _ in range(3):                        # the node keeps up (its queue holds 10 summaries)
                executor.spin_once(timeout_sec=0.01)
        while len(got) < 4 and time.monotonic() < deadline + 5:
            executor.spin_once(timeout_sec=0.05)
        steps = [step for k in sorted(carried) for step in carried[k]]
        assert [(m.index, m.frame_index) for m in got] == [(s.index, s.frame) for s in steps]
        assert [stamp_to_ns(m.header.stamp) for m in got] == [s.stamp_ns for s in steps]
        assert [stamp_to_ns(m.strike) for m in got] == [s.stamp_ns - 100_000_000 for s in steps]
        assert [m.foot for m in got] == [GaitStep.RIGHT, GaitStep.LEFT, GaitStep.RIGHT, GaitStep.LEFT]
        assert np.isnan(got[0].step_length) and [m.step_length for m in got[1:]] == [0.7, 0.65, 0.7]
        assert [m.position.x for m in got] == pytest.approx([0.0, 0.7, 1.4, 2.1])
        assert all((m.step_width, m.step_time, m.stride_time, m.cadence, m.speed) == (0.2, 0.5, 1.0, 120.0, 1.4)
                   for m in got)
        assert all(m.header.frame_id == "world" for m in got)
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()


def test_the_skeleton_lines_are_the_body_models_edges():
    """The pose publisher's skeleton lines join the MAP markers along model.body.SKELETON_EDGES, as the overlays
    draw them (one edge list)."""
    from visualization_msgs.msg import Marker

    from awalker_tracker.model.body import SKELETON_EDGES
    from awalker_tracker.nodes.messages import summary_to_msg
    from awalker_tracker.nodes.pose_publisher_node import MarkerBuilder, body_cylinders

    s = make_summary(10, 0, np.random.default_rng(2))
    array = MarkerBuilder(body_cylinders(BodyDescription.default())).build(summary_to_msg(s))
    lines, = [m for m in array.markers if m.type == Marker.LINE_LIST]
    got = np.array([[p.x, p.y, p.z] for p in lines.points])
    want = np.array([s.map_markers[MARKER_NAMES.index(name)] for edge in SKELETON_EDGES for name in edge])
    np.testing.assert_allclose(got, want)
