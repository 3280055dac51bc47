"""Features node in an rclpy executor: every image -> one ImageFeatures with its stamp; conversions."""
from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.vision.foreground import start_pose_labels
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
from awalker_tracker.vision.flow import FlowConfig


def stamps_first() -> int:
    return 2_000_000_000


def _scene():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vision"))
    import vision_scene

    return vision_scene


def scene_camera():
    return _scene().side_camera()


def scene_frames():
    s = _scene()
    background_image, noisy, render_frames, side_camera, walking_poses = (
        s.background_image, s.noisy, s.render_frames, s.side_camera, s.walking_poses)

    cam = side_camera()
    bg = background_image(cam)
    rng = np.random.default_rng(0)
    frames, _ = render_frames(cam, walking_poses(4), bg)
    return [noisy(bg, rng) for _ in range(3)] + frames


def image_msg(rgb: np.ndarray, stamp_ns: int, encoding: str = "rgb8"):
    from sensor_msgs.msg import Image

    from awalker_tracker.nodes.messages import header

    data = rgb if encoding == "rgb8" else rgb[..., ::-1]
    msg = Image(header=header(stamp_ns, "cam_optical_frame"), height=rgb.shape[0], width=rgb.shape[1],
                encoding=encoding, step=rgb.shape[1] * 3)
    msg.data = np.ascontiguousarray(data).tobytes()
    return msg


def test_features_message_roundtrip():
    from awalker_tracker.nodes.features_node import features_from_msg, features_to_msg
    from awalker_tracker.nodes.messages import header

    frames = scene_frames()
    extractor = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2, flow=FlowConfig(cell_size=8)))
    out = [extractor.process(f) for f in frames][-1]
    msg = features_to_msg(out, header(5, "cam_optical_frame"), "cam")
    back = features_from_msg(msg)
    assert out.occlusion is None and back.occlusion is None and len(msg.occlusion_map) == 0   # no mask, none sent
    assert back.classes == out.classes and back.downsample == 2 and back.map_shape == out.map_shape
    assert np.array_equal(back.llr, out.llr)
    # an occlusion mask: its map pixels travel with the ratios (which are 0 there)
    mask = np.zeros(frames[-1].shape[:2], np.uint8)
    mask[-9:, :20] = 255
    masked = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2, flow=FlowConfig(cell_size=8)))
    out_masked = [masked.process(f, occlusion_mask=mask) for f in frames][-1]
    back_masked = features_from_msg(features_to_msg(out_masked, header(5, "cam_optical_frame"), "cam"))
    h, w = out_masked.map_shape
    assert back_masked.occlusion.shape == (h, w) and np.array_equal(back_masked.occlusion, out_masked.occlusion)
    assert back_masked.occlusion[-5:, :10].all() and not back_masked.occlusion[: h - 5].any()
    assert not back_masked.llr[:, back_masked.occlusion].any()
    assert np.array_equal(back.flow.flow, out.flow.flow) and np.array_equal(back.flow.valid, out.flow.valid)
    assert np.array_equal(back.flow.covariance, out.flow.covariance)
    assert np.array_equal(back.flow.centers, out.flow.centers) and back.flow.cell_size == 8
    msg.occlusion_map = [0, 1, 0]
    with pytest.raises(InputError, match="occlusion map of 3 pixels"):
        features_from_msg(msg)
    msg.occlusion_map = []
    msg.log_likelihood_ratio = msg.log_likelihood_ratio[:-1]
    with pytest.raises(InputError, match="ratios"):
        features_from_msg(msg)


def test_node_publishes_features_for_every_image(ros_context):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import CameraInfo, CompressedImage, Image
    from std_msgs.msg import String

    from awalker_msgs.msg import ImageFeatures
    from awalker_tracker.nodes.features_node import FeatureNode, features_from_msg
    from awalker_tracker.nodes.messages import header, stamp_to_ns

    frames = scene_frames()
    cam = scene_camera()
    node = FeatureNode(context=ros_context, parameter_overrides=[
        Parameter("camera_name", value="cam"), Parameter("downsample", value=2), Parameter("flow_cell_size", value=8)])
    probe = Node("probe", context=ros_context)
    received: list = []
    probe.create_subscription(ImageFeatures, "/cam/features", received.append, QoSProfile(depth=50))
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    start_pub = probe.create_publisher(String, "/awalker/start_description", latched)
    image_pub = probe.create_publisher(Image, "/cam/image_raw", QoSProfile(depth=50))
    compressed_pub = probe.create_publisher(CompressedImage, "/cam/image_raw/compressed", QoSProfile(depth=50))
    info_pub = probe.create_publisher(CameraInfo, "/cam/camera_info", QoSProfile(depth=10))
    pose_pub = probe.create_publisher(PoseStamped, "/cam/camera_pose", latched)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)
    try:
        start_pub.publish(String(data="start: {frame: 3, position: [0.0, 0.0], heading: 0.0, speed: 1.3, "
                                      "step_length: 0.7, stance_leg: left}\n"))
        pose = PoseStamped()
        pose.header.frame_id = "world"
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in cam.position)
        q = cam.quaternion
        pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z, pose.pose.orientation.w = (
            float(v) for v in q)
        pose_pub.publish(pose)
        deadline = time.monotonic() + 10
        while (node.extractor.background_frames != 3 or image_pub.get_subscription_count() == 0
               or compressed_pub.get_subscription_count() == 0 or node._pose is None
               or info_pub.get_subscription_count() == 0) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        info_pub.publish(CameraInfo(header=header(stamps_first(), "cam_optical_frame"), width=cam.width,
                                    height=cam.height, k=[float(v) for v in cam.K.ravel()], d=[]))
        while node._info is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert node.extractor.background_frames == 3      # learned from the start description
        stamps = [2_000_000_000 + k * 33_333_333 for k in range(len(frames))]
        for k, (stamp, rgb) in enumerate(zip(stamps, frames)):
            if k == 4:
                msg = CompressedImage(header=header(stamp, "cam_optical_frame"), format="png")
                msg.data = cv2.imencode(".png", rgb[..., ::-1])[1].tobytes()
                compressed_pub.publish(msg)
            else:
                image_pub.publish(image_msg(rgb, stamp))
            if k == 2:
                bad = image_msg(rgb, stamp + 1)
                bad.encoding = "yuv422"
                image_pub.publish(bad)                      # logged, counted, a frame without evidence
            while len(received) < k + 1 + (k >= 2) and time.monotonic() < deadline + 10:
                executor.spin_once(timeout_sec=0.05)
        for _ in range(5):
            executor.spin_once(timeout_sec=0.05)
        assert [stamp_to_ns(m.header.stamp) for m in received] == stamps[:3] + [stamps[2] + 1] + stamps[3:]
        assert node.stats.undecodable == 1 and node.stats.skipped == 0 and node.stats.frames == len(frames) + 1
        # the undecodable image: zero maps and no flow, and the frame after it no flow across the gap
        blank = features_from_msg(received.pop(3))
        assert not blank.llr.any() and not blank.flow.valid.any() and blank.map_shape == (cam.height // 2, cam.width // 2)
        assert not features_from_msg(received[3]).flow.valid.any()
        # the frame that was to learn the foreground came after it: learned from the next one, from the start pose
        assert node.stats.foreground_from == "start pose"
        # Same maps as the core extractor fed the same frames (and the same start-pose labels).
        reference = FeatureExtractor(FeatureConfig(background_frames=3, downsample=2, flow=FlowConfig(cell_size=8)))
        labels = start_pose_labels(BodyDescription.default(), cam, (0.0, 0.0), 0.0, 0.7, 0)
        expected = [reference.process(f, class_labels=labels, fill_with_bands=True) for f in frames]
        for msg, exp in zip(received, expected):
            got = features_from_msg(msg)
            assert msg.camera_name == "cam" and msg.header.frame_id == "cam_optical_frame"
            assert np.allclose(got.llr, exp.llr) and (msg is received[3] or np.array_equal(got.flow.valid, exp.flow.valid))
        assert not np.any(features_from_msg(received[2]).llr)        # background learning: no information
        assert features_from_msg(received[-1]).llr.max() > 5         # the person is seen
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()


def _features_with_a_broken_flow(ros_context, monkeypatch, error: Exception, frames: int):
    """A features node (flow on its own thread) whose flow estimate raises ``error`` for the second frame (the first
    with a flow), fed ``frames`` images; spins until it published the others or the executor raised. Returns
    (the node's stats, the stamps published, what the executor raised or None)."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Image

    from awalker_msgs.msg import ImageFeatures
    from awalker_tracker.nodes.features_node import FeatureNode
    from awalker_tracker.nodes.messages import stamp_to_ns
    from awalker_tracker.vision import flow as flow_module

    monkeypatch.setenv("AWALKER_THREADS", "2")
    estimate = flow_module.GridFlow.estimate
    calls: list[int] = []

    def broken_once(self, prev_grey, grey):
        calls.append(1)
        if len(calls) == 1:
            raise error
        return estimate(self, prev_grey, grey)

    monkeypatch.setattr(flow_module.GridFlow, "estimate", broken_once)
    node = FeatureNode(context=ros_context, parameter_overrides=[Parameter("camera_name", value="cam")])
    probe = Node("probe", context=ros_context)
    received: list = []
    probe.create_subscription(ImageFeatures, "/cam/features", received.append, QoSProfile(depth=50))
    image_pub = probe.create_publisher(Image, "/cam/image_raw", QoSProfile(depth=50))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(probe)
    images = scene_frames()[:frames]
    raised = None
    try:
        deadline = time.monotonic() + 10
        while image_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for k, rgb in enumerate(images):
            image_pub.publish(image_msg(rgb, 2_000_000_000 + k * 33_333_333))
        try:
            while len(received) + node.stats.skipped < len(images) and time.monotonic() < deadline + 10:
                executor.spin_once(timeout_sec=0.05)
            for _ in range(5):
                executor.spin_once(timeout_sec=0.05)
        except Exception as exc:
            raised = exc
        return node.stats, [stamp_to_ns(m.header.stamp) for m in received], raised
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()


def test_an_error_on_the_flow_thread_is_raised_in_the_executor(ros_context, monkeypatch):
    """A failure while a frame's flow is estimated (on the extractor's thread) is not lost in that thread: the
    executor spinning the node raises it."""
    _, _, raised = _features_with_a_broken_flow(ros_context, monkeypatch, RuntimeError("flow kernel broke"), 3)
    assert isinstance(raised, RuntimeError) and "awalker_features (cam): features failed" in str(raised)
    assert "flow kernel broke" in str(raised.__cause__)


def test_a_frame_refused_on_the_flow_thread_is_skipped_and_counted(ros_context, monkeypatch):
    """A ValueError on the flow thread skips that frame, as one in the image callback does; the frames after it
    are published, their flow from the skipped frame's image."""
    stats, stamps, raised = _features_with_a_broken_flow(ros_context, monkeypatch, ValueError("bad cell grid"), 4)
    assert raised is None and stats.skipped == 1 and stats.frames == 3
    assert stamps == [2_000_000_000 + k * 33_333_333 for k in (0, 2, 3)]


def test_node_requires_a_camera_name(ros_context):
    from awalker_tracker.nodes.features_node import FeatureNode

    with pytest.raises(InputError, match="camera_name"):
        FeatureNode(context=ros_context)


def test_start_and_body_file_parameters(ros_context, tmp_path):
    """The start file sets the background-only frames at once; bad files are named in the error."""
    from rclpy.parameter import Parameter

    from awalker_tracker.nodes.features_node import FeatureNode

    start = tmp_path / "start.yaml"
    start.write_text("start: {frame: 7, position: [0, 0], heading: 0, speed: 1.3, stance_leg: left}\n")
    node = FeatureNode(context=ros_context, parameter_overrides=[
        Parameter("camera_name", value="cam0"), Parameter("start_description", value=str(start))])
    try:
        assert node.extractor.background_frames == 7 and node._start.frame == 7
    finally:
        node.destroy_node()
    with pytest.raises(InputError, match=r"missing\.yaml: cannot read start description"):
        FeatureNode(context=ros_context, parameter_overrides=[
            Parameter("camera_name", value="cam0"), Parameter("start_description", value=str(tmp_path / "missing.yaml"))])
    (tmp_path / "body.yaml").write_text("body: {upper_leg_length: -1}\n")
    with pytest.raises(InputError, match=r"body\.yaml"):
        FeatureNode(context=ros_context, parameter_overrides=[
            Parameter("camera_name", value="cam0"), Parameter("body_description", value=str(tmp_path / "body.yaml"))])


def test_features_for_every_frame_of_a_replayed_bag(ros_context, tmp_path):
    """A written sequence bag (compressed png, start description, camera pose) replayed in lockstep
    into the node: one ImageFeatures per frame, in order, start-pose foreground learning."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile
    from std_msgs.msg import Header

    from awalker_msgs.msg import ImageFeatures
    from awalker_tools.bagio import START_DESCRIPTION_TOPIC, SequenceWriter
    from awalker_tools.replay import ReplayConfig, Replayer
    from awalker_tracker.nodes.features_node import FeatureNode, features_from_msg
    from awalker_tracker.nodes.messages import stamp_to_ns

    frames = scene_frames()
    cam = scene_camera()
    stamps = [1_000_000_000 + k * 33_333_333 for k in range(len(frames))]
    bag = tmp_path / "scene.bag"
    with SequenceWriter(bag, [cam], compressed=True) as writer:
        writer.write_text(START_DESCRIPTION_TOPIC, stamps[0], "start: {frame: 3, position: [0.0, 0.0], heading: 0.0, "
                                                             "speed: 1.3, step_length: 0.7, stance_leg: left}\n")
        for stamp, rgb in zip(stamps, frames):
            writer.write_frame(stamp, {cam.name: rgb})
    node = FeatureNode(context=ros_context, parameter_overrides=[
        Parameter("camera_name", value=cam.name), Parameter("downsample", value=2), Parameter("flow_cell_size", value=8)])
    driver = Node("replay_driver", context=ros_context)
    acker = Node("acker", context=ros_context)
    ack = acker.create_publisher(Header, "/awalker/ack", QoSProfile(depth=50))
    received: list = []

    def on_features(msg):
        received.append(msg)
        ack.publish(Header(stamp=msg.header.stamp))

    acker.create_subscription(ImageFeatures, f"/{cam.name}/features", on_features, QoSProfile(depth=50))
    executor = SingleThreadedExecutor(context=ros_context)
    for n in (node, driver, acker):
        executor.add_node(n)
    try:
        replayer = Replayer(driver, bag, ReplayConfig(lockstep=True, wait_for_subscribers=10.0, ack_timeout=20.0))
        deadline = time.monotonic() + 60
        while replayer.step() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=replayer.next_wait())
        for _ in range(10):
            executor.spin_once(timeout_sec=0.02)
        assert replayer.summary.frames == len(frames)
        assert [stamp_to_ns(m.header.stamp) for m in received] == stamps
        assert node.stats.foreground_from == "start pose" and node.stats.skipped == 0
        maps = [features_from_msg(m) for m in received]
        assert not maps[2].llr.any() and maps[3].llr.max() > 5 and maps[-1].flow.valid.mean() > 0.5
    finally:
        executor.shutdown()
        for n in (node, driver, acker):
            n.destroy_node()


class MaskRig:
    """A features node for camera ``cam`` with occlusion masks, a probe publishing images and masks (the right
    half of each frame hidden) and receiving the features, one executor; ``close()`` when done."""

    def __init__(self, ros_context, mask_wait_s: float) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.parameter import Parameter
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import Image

        from awalker_msgs.msg import ImageFeatures
        from awalker_tracker.nodes.features_node import FeatureNode

        self.frames = scene_frames()
        self.stamps = [3_000_000_000 + k * 33_333_333 for k in range(len(self.frames))]
        self.node = FeatureNode(context=ros_context, parameter_overrides=[
            Parameter("camera_name", value="cam"), Parameter("downsample", value=2),
            Parameter("flow_cell_size", value=8), Parameter("background_frames", value=3),
            Parameter("mask_wait_s", value=mask_wait_s)])
        self.probe = Node("probe", context=ros_context)
        self.received: list = []
        self.probe.create_subscription(ImageFeatures, "/cam/features", self.received.append, QoSProfile(depth=50))
        self.image_pub = self.probe.create_publisher(Image, "/cam/image_raw", QoSProfile(depth=50))
        self.mask_pub = self.probe.create_publisher(Image, "/cam/occlusion_mask", QoSProfile(depth=50))
        self.executor = SingleThreadedExecutor(context=ros_context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.deadline = time.monotonic() + 10
        self.spin_until(lambda: self.image_pub.get_subscription_count() > 0 and self.mask_pub.get_subscription_count() > 0
                        and self.node.count_publishers("/cam/occlusion_mask") > 0)

    def spin_until(self, done) -> None:
        while not done() and time.monotonic() < self.deadline + 10:
            self.executor.spin_once(timeout_sec=0.05)

    def publish_image(self, k: int) -> None:
        self.image_pub.publish(image_msg(self.frames[k], self.stamps[k]))

    def publish_mask(self, k: int) -> None:
        from sensor_msgs.msg import Image

        from awalker_tracker.nodes.messages import header

        h, w = self.frames[k].shape[:2]
        occluded = np.zeros((h, w), np.uint8)
        occluded[:, w // 2:] = 255
        mask = Image(header=header(self.stamps[k], "cam_optical_frame"), height=h, width=w, encoding="mono8", step=w)
        mask.data = occluded.tobytes()
        self.mask_pub.publish(mask)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()


def test_occlusion_mask_published_after_its_image_is_applied(ros_context):
    """Replay publishes a frame's mask just after its image: the node holds the image for it. A frame
    whose mask never comes is processed after mask_wait_s, counted, and still published."""
    from awalker_tracker.nodes.features_node import features_from_msg
    from awalker_tracker.nodes.messages import stamp_to_ns

    rig = MaskRig(ros_context, mask_wait_s=0.3)
    received, count = rig.received, len(rig.frames)
    try:
        for k in range(count):
            rig.publish_image(k)
            if k != count - 1:                       # the last frame's mask never comes
                rig.publish_mask(k)
            rig.spin_until(lambda: len(received) >= k + 1)
        assert [stamp_to_ns(m.header.stamp) for m in received] == rig.stamps
        assert rig.node.stats.frames == count and rig.node.stats.frames_without_mask == 1
        half = features_from_msg(received[0]).map_shape[1] // 2
        masked = features_from_msg(received[-2])
        assert not np.any(masked.llr[:, :, half:]) and np.abs(masked.llr[:, :, :half - 1]).max() > 1
        assert not masked.flow.valid[:, masked.flow.valid.shape[1] // 2 + 1:].any()
        unmasked = features_from_msg(received[-1])  # processed after mask_wait_s without its mask
        assert np.abs(unmasked.llr[:, :, half + 1:]).max() > 1
    finally:
        rig.close()


def test_masks_that_came_in_time_are_applied_when_the_node_was_kept_waiting(ros_context):
    """Two frames in flight (image, image, mask, mask) and the node's executor kept from running for longer
    than mask_wait_s: the hold timers and the masks are ready together, and rclpy runs timers first. Both
    frames must still get their masks, in order (before: the first image went out unmasked whenever the
    machine was busy, so runs of one bag differed)."""
    from awalker_tracker.nodes.features_node import features_from_msg
    from awalker_tracker.nodes.messages import stamp_to_ns

    rig = MaskRig(ros_context, mask_wait_s=0.1)
    received = rig.received
    try:
        for k in range(0, len(rig.frames) - 1, 2):
            rig.publish_image(k)
            rig.publish_image(k + 1)
            rig.spin_until(lambda: bool(rig.node._held))   # the first image is taken and held; its timer waits
            rig.publish_mask(k)
            rig.publish_mask(k + 1)
            time.sleep(0.3)                          # the node kept from running past mask_wait_s
            rig.spin_until(lambda: len(received) >= k + 2)
        assert [stamp_to_ns(m.header.stamp) for m in received] == rig.stamps[: len(received)]
        assert len(received) >= 4 and rig.node.stats.frames_without_mask == 0
        half = features_from_msg(received[0]).map_shape[1] // 2
        for msg in received[3:]:                     # after the background frames: the right half is hidden
            assert not np.any(features_from_msg(msg).llr[:, :, half:])
    finally:
        rig.close()
