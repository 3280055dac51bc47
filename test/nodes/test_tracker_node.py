"""Tracker node in-process: two cameras' features paired by stamp, acks for every frame (also for a
frame one camera never delivered), posteriors stamped with the image stamps, flushed when idle."""
from __future__ import annotations

import time

import numpy as np
import pytest


def _features_msg(stamp_ns: int, cam: str):
    from awalker_tracker.model.body import PART_CLASSES
    from awalker_tracker.nodes.features_node import features_to_msg
    from awalker_tracker.nodes.messages import header
    from awalker_tracker.vision.features import FrameFeatures
    from awalker_tracker.vision.flow import FlowGrid

    rows, cols, cell = 4, 5, 16
    centers = np.stack(np.meshgrid(np.arange(cols) * cell + 8.0, np.arange(rows) * cell + 8.0), -1)
    flow = FlowGrid(centers.astype(np.float32), np.zeros((rows, cols, 2), np.float32),
                    np.tile(np.eye(2, dtype=np.float32), (rows, cols, 1, 1)), np.zeros((rows, cols), bool), cell)
    feats = FrameFeatures(PART_CLASSES, np.zeros((len(PART_CLASSES), 16, 20), np.float32), 4, 80, 64, flow)
    return features_to_msg(feats, header(stamp_ns, f"{cam}_optical_frame"), cam)


@pytest.fixture
def tracker_files(tmp_path):
    from awalker_tracker.inference.filter_model import StartDescription
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.vision.camera import Camera, save_calibration

    cams = [Camera.look_at("cam0", 80, 64, 60.0, np.array([0.0, -6.0, 1.5]), np.array([0.0, 0.0, 0.9])),
            Camera.look_at("cam1", 80, 64, 60.0, np.array([6.0, 0.0, 1.5]), np.array([0.0, 0.0, 0.9]))]
    save_calibration(cams, tmp_path / "calibration.yaml")
    (tmp_path / "start.yaml").write_text(StartDescription(1, (0.0, 0.0), 0.0, 1.3, 0.7, 0).to_yaml_text())
    (tmp_path / "body.yaml").write_text(BodyDescription.default().to_yaml_text())
    return tmp_path


def test_tracker_node_pairs_cameras_acks_and_publishes(ros_context, tracker_files):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Header

    from awalker_msgs.msg import ImageFeatures, PosteriorSummary
    from awalker_tracker.nodes.messages import stamp_to_ns
    from awalker_tracker.nodes.tracker_node import TrackerNode

    node = TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=["cam0", "cam1"]),
        Parameter("calibration", value=str(tracker_files / "calibration.yaml")),
        Parameter("start_description", value=str(tracker_files / "start.yaml")),
        Parameter("body_description", value=str(tracker_files / "body.yaml")),
        Parameter("num_particles", value=50), Parameter("idle_flush_s", value=0.5)])
    probe = Node("probe", context=ros_context)
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pubs = {c: probe.create_publisher(ImageFeatures, f"/{c}/features", qos) for c in ("cam0", "cam1")}
    posteriors, acks = [], []
    probe.create_subscription(PosteriorSummary, "/awalker/posterior", posteriors.append, qos)
    probe.create_subscription(Header, "/awalker/ack", acks.append, qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)
    stamps = [2_000_000_000 + k * 33_333_333 for k in range(8)]
    try:
        deadline = time.monotonic() + 5
        while any(p.get_subscription_count() == 0 for p in pubs.values()) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for k, stamp in enumerate(stamps):
            pubs["cam0"].publish(_features_msg(stamp, "cam0"))
            if k != 4:                                   # cam1 never delivers frame 4
                pubs["cam1"].publish(_features_msg(stamp, "cam1"))
            for _ in range(5):
                executor.spin_once(timeout_sec=0.02)
        deadline = time.monotonic() + 10
        while len(posteriors) < 7 and time.monotonic() < deadline:     # frames 1-7
            executor.spin_once(timeout_sec=0.05)
        for _ in range(10):
            executor.spin_once(timeout_sec=0.02)
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
    assert sorted(stamp_to_ns(a.stamp) for a in acks) == stamps          # every frame acknowledged once
    tracked = stamps[1:]                             # start frame 1; frame 4 tracked with cam0 alone
    assert [stamp_to_ns(p.header.stamp) for p in posteriors] == tracked
    assert [p.frame_index for p in posteriors] == [1, 2, 3, 4, 5, 6, 7]     # bag frame indices kept
    assert all(p.num_particles == 50 and len(p.map_pose.markers) == 13 for p in posteriors)
    assert len(node.stats.sync_issues) == 1 and "tracked without camera(s) cam1" in node.stats.sync_issues[0]


def test_tracker_node_needs_cameras(ros_context):
    from awalker_tracker.errors import InputError
    from awalker_tracker.nodes.tracker_node import TrackerNode

    with pytest.raises(InputError, match="'cameras' is required"):
        TrackerNode(context=ros_context)


def test_tracker_node_checks_follow_near(ros_context):
    from rclpy.parameter import Parameter

    from awalker_tracker.errors import InputError
    from awalker_tracker.nodes.tracker_node import TrackerNode

    for bad in ([1.0], [float("nan"), 0.0]):
        with pytest.raises(InputError, match="parameter 'follow_near'"):
            TrackerNode(context=ros_context, parameter_overrides=[
                Parameter("cameras", value=["cam0"]), Parameter("follow_near", value=bad)])
    node = TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=["cam0"]), Parameter("follow_near", value=[1.0, -2.0])])
    try:
        assert node.autostart_config.follow_near == (1.0, -2.0)
    finally:
        node.destroy_node()


def test_tracker_node_checks_leg_scale_spread(ros_context):
    from rclpy.parameter import Parameter

    from awalker_tracker.errors import InputError
    from awalker_tracker.nodes.tracker_node import TrackerNode

    with pytest.raises(InputError, match="parameter 'leg_scale_spread'"):
        TrackerNode(context=ros_context, parameter_overrides=[
            Parameter("cameras", value=["cam0"]), Parameter("leg_scale_spread", value=-0.04)])
    node = TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=["cam0"]), Parameter("leg_scale_spread", value=0.04)])
    try:
        assert node.leg_scale_spread == 0.04
    finally:
        node.destroy_node()


def test_tracker_node_checks_the_pelvis_ceiling(ros_context):
    from rclpy.parameter import Parameter

    from awalker_tracker.errors import InputError
    from awalker_tracker.nodes.tracker_node import TrackerNode

    for name, bad in (("pelvis_ceiling", 1.2), ("pelvis_ceiling_min_cameras", 0)):
        with pytest.raises(InputError, match="parameters 'pelvis_ceiling', 'pelvis_ceiling_min_cameras'"):
            TrackerNode(context=ros_context, parameter_overrides=[
                Parameter("cameras", value=["cam0"]), Parameter(name, value=bad)])


@pytest.mark.parametrize("fitted_frame", [1, 3])
def test_a_start_without_stance_leg_takes_the_fitted_one_at_its_frame(ros_context, tracker_files, fitted_frame):
    """``fitted_start``: a start naming no stance leg takes the fitted start's leg when both start at the same
    frame (and writes it to start_output); fitted at another frame, its leg is not used (both sampled)."""
    from dataclasses import replace

    from rclpy.parameter import Parameter

    from awalker_tracker.inference.filter_model import StartDescription
    from awalker_tracker.model.walker import RIGHT
    from awalker_tracker.nodes.tracker_node import TrackerNode

    given = StartDescription(1, (0.0, 0.0), 0.0, 1.3, 0.7, None)
    (tracker_files / "start.yaml").write_text(given.to_yaml_text())
    (tracker_files / "fitted.yaml").write_text(replace(given, frame=fitted_frame, stance_leg=RIGHT).to_yaml_text())
    node = TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=["cam0", "cam1"]),
        Parameter("calibration", value=str(tracker_files / "calibration.yaml")),
        Parameter("start_description", value=str(tracker_files / "start.yaml")),
        Parameter("fitted_start", value=str(tracker_files / "fitted.yaml")),
        Parameter("start_output", value=str(tracker_files / "used.yaml")),
        Parameter("body_description", value=str(tracker_files / "body.yaml")),
        Parameter("num_particles", value=50), Parameter("frame_rate", value=30.0)])
    try:
        assert node._make_tracker()
        used = node.tracker.model.start.stance_leg
    finally:
        node.destroy_node()
    if fitted_frame == given.frame:
        assert used == RIGHT and StartDescription.from_yaml(tracker_files / "used.yaml").stance_leg == RIGHT
    else:
        assert used is None and not (tracker_files / "used.yaml").exists()


def test_a_bad_camera_info_is_logged_and_not_used(ros_context):
    """Cameras from /<cam>/camera_info + /<cam>/camera_pose go through the one validated builder
    (vision.camera.camera_from_info): a NaN in K is refused (the node carries on) until a valid one comes."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo

    from awalker_tracker.nodes.tracker_node import TrackerNode

    node = TrackerNode(context=ros_context, parameter_overrides=[Parameter("cameras", value=["cam0"]),
                                                                 Parameter("num_particles", value=50)])
    probe = Node("probe", context=ros_context)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    info_pub = probe.create_publisher(CameraInfo, "/cam0/camera_info", QoSProfile(depth=10))
    pose_pub = probe.create_publisher(PoseStamped, "/cam0/camera_pose", latched)
    errors: list[str] = []
    node.get_logger().error = lambda text, **_: errors.append(text)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)

    def spin_until(done, timeout: float = 5.0) -> None:
        deadline = time.monotonic() + timeout
        while not done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)

    try:
        pose = PoseStamped()
        pose.header.frame_id = "world"
        pose.pose.position.y, pose.pose.position.z = -5.0, 1.5
        pose.pose.orientation.x, pose.pose.orientation.w = -0.70710678, 0.70710678
        pose_pub.publish(pose)
        bad = CameraInfo(width=80, height=64, distortion_model="plumb_bob")
        bad.k = [float("nan"), 0.0, 40.0, 0.0, 60.0, 32.0, 0.0, 0.0, 1.0]
        spin_until(lambda: info_pub.get_subscription_count() > 0)
        for _ in range(3):                             # one error logged, however often it comes
            info_pub.publish(bad)
            spin_until(lambda: False, 0.3)
        assert node.cameras == {} and len(errors) == 1
        assert errors[0].startswith("/cam0/camera_info: k: contains NaN or infinity") and "not used" in errors[0]
        good = CameraInfo(width=80, height=64, distortion_model="plumb_bob")
        good.k = [60.0, 0.0, 40.0, 0.0, 60.0, 32.0, 0.0, 0.0, 1.0]
        info_pub.publish(good)
        spin_until(lambda: "cam0" in node.cameras)
        np.testing.assert_allclose(node.cameras["cam0"].position, [0.0, -5.0, 1.5])
        np.testing.assert_allclose(node.cameras["cam0"].rotation[:, 2], [0.0, 1.0, 0.0], atol=1e-7)  # looks along +y
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


def _stream_features(ros_context, tracker_files, max_lag_s: float, frames: int = 60, rate_hz: float = 60.0):
    """Publish one camera's features of ``frames`` frames at ``rate_hz`` (as a camera would, whatever the tracker
    does) to a tracker node too slow for that rate; returns the node's stats, the acks' stamps, the posteriors'
    stamps and the frames' stamps."""
    import threading

    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Header

    from awalker_msgs.msg import ImageFeatures, PosteriorSummary
    from awalker_tracker.inference.filter_model import StartDescription
    from awalker_tracker.nodes.messages import stamp_to_ns
    from awalker_tracker.nodes.tracker_node import TrackerNode

    (tracker_files / "start0.yaml").write_text(StartDescription(0, (0.0, 0.0), 0.0, 1.3, 0.7, 0).to_yaml_text())
    node = TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=["cam0"]), Parameter("calibration", value=str(tracker_files / "calibration.yaml")),
        Parameter("start_description", value=str(tracker_files / "start0.yaml")),
        Parameter("body_description", value=str(tracker_files / "body.yaml")),
        Parameter("num_particles", value=20000), Parameter("lookahead", value=0),
        Parameter("idle_flush_s", value=60.0), Parameter("max_lag_s", value=max_lag_s)])
    probe = Node("camera", context=ros_context)
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = probe.create_publisher(ImageFeatures, "/cam0/features", qos)
    acks, posteriors = [], []
    probe.create_subscription(Header, "/awalker/ack", lambda m: acks.append(stamp_to_ns(m.stamp)), qos)
    probe.create_subscription(PosteriorSummary, "/awalker/posterior", posteriors.append, qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)
    stamps = [2_000_000_000 + round(k * 1e9 / rate_hz) for k in range(frames)]
    messages = [_features_msg(s, "cam0") for s in stamps]

    def camera() -> None:
        start = time.monotonic()
        for k, msg in enumerate(messages):
            time.sleep(max(0.0, start + k / rate_hz - time.monotonic()))
            pub.publish(msg)

    try:
        deadline = time.monotonic() + 5
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        thread = threading.Thread(target=camera)
        thread.start()
        deadline = time.monotonic() + 60
        while len(acks) < frames and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        thread.join()
        deadline = time.monotonic() + 5
        while len(posteriors) < node.stats.frames_tracked and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
    return node.stats, acks, [stamp_to_ns(p.header.stamp) for p in posteriors], stamps


def test_a_tracker_slower_than_the_camera_skips_frames_by_stamp_and_keeps_up(ros_context, tracker_files):
    """Features at 60 Hz into a filter that needs longer than a frame period per frame (20000 particles): with
    max_lag_s 0.1 frames that waited longer are skipped and acknowledged, the filter steps over them by their
    stamps, and no frame it filters had waited longer; with max_lag_s 0 (never skip) every frame is filtered and
    the tracker falls behind by seconds."""
    stats, acked, published, stamps = _stream_features(ros_context, tracker_files, max_lag_s=0.1)
    assert sorted(acked) == stamps                               # every frame acknowledged, skipped ones too
    assert stats.frames_skipped > 0 and stats.frames_tracked + stats.frames_skipped == len(stamps)
    assert published == sorted(published) and set(published) <= set(stamps)
    assert len(published) == stats.frames_tracked

    behind, _, all_published, _ = _stream_features(ros_context, tracker_files, max_lag_s=0.0)
    assert behind.frames_skipped == 0 and len(all_published) == len(stamps)
    # the time the tracker needs per frame, measured without skipping: more than the camera's period
    per_frame = behind.seconds_in_filter / behind.frames_tracked
    assert per_frame > 1.0 / 60.0, per_frame
    # keeping up: no frame filtered had waited longer than max_lag_s; never skipping, the last ones waited ~ the
    # time the filter needed for all the frames before them beyond the camera's 1 s
    assert stats.largest_lag_s <= 0.1 and behind.largest_lag_s > 0.5, (stats.largest_lag_s, behind.largest_lag_s)


def test_an_automatic_start_found_only_at_the_end_still_tracks(ros_context, tmp_path):
    """Hands off, a clip shorter than the start finder's fit window (1 s of walking; 1.3 s to fit): the finder
    has taken every frame and found the walk without finishing its fit when the stream ends; the final flush
    starts from what it has and tracks the frames kept since the start (before, nothing was tracked: no frame
    was left pending at the end, so the finder was never asked to finish)."""
    import sys
    from pathlib import Path

    from rclpy.parameter import Parameter

    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.nodes.features_node import features_to_msg
    from awalker_tracker.nodes.messages import header
    from awalker_tracker.nodes.tracker_node import TrackerNode
    from awalker_tracker.vision.camera import save_calibration

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "inference"))
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vision"))
    from test_autostart import side_scene, walking  # noqa: E402
    from vision_scene import noisy, render_frames  # noqa: E402

    camera, background, rng, extractor = side_scene()
    features = [extractor.process(noisy(background, rng)) for _ in range(4)]
    images, _ = render_frames(camera, walking(30, x0=-0.8), background, seed=2)
    features += [extractor.process(image) for image in images]
    save_calibration([camera], tmp_path / "calibration.yaml")
    node = TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=[camera.name]), Parameter("calibration", value=str(tmp_path / "calibration.yaml")),
        Parameter("auto_start", value=True), Parameter("num_particles", value=50), Parameter("frame_rate", value=30.0),
        Parameter("estimate_body", value=True)])
    try:
        for k, f in enumerate(features):
            node._on_features(camera.name, features_to_msg(f, header(1_000_000_000 + k * 33_333_333, "side_optical"),
                                                           camera.name))
        assert node.start is None and node._finder is not None and not node._pending   # all taken, none fitted
        node.flush()
        assert node.start is not None and node.start_found_automatically and 8 <= node.start.frame <= 24
        assert node.tracker is not None and node.stats.summaries == len(features) - node.start.frame
        # no body description: the body scaled to the seen height, with one camera's proportions (the default's)
        height = node._finder.estimated_height()
        assert node.body == BodyDescription.from_seen_height(float(np.clip(height, 1.2, 2.1)), 1)
        assert node.body.leg_length / node.body.height == pytest.approx(
            BodyDescription.default().leg_length / BodyDescription.default().height)
    finally:
        node.destroy_node()
