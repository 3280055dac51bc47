"""Replay a bag into a subscriber node in the same process: every frame once, in order, bytes intact."""
from __future__ import annotations

import struct
import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from awalker_tools.bagio import SequenceReader, open_reader, iter_messages
from awalker_tools.replay import (
    Batch,
    ReplayConfig,
    Replayer,
    ReplayNode,
    header_stamp_ns,
    iter_batches,
    run_replay,
    unmatched_local_topics,
)
from awalker_tools.typestore import typestore
from awalker_tracker.errors import InputError

from replay_helpers import CAMERAS, FRAME_PERIOD_NS, Receiver, make_bag


def _spin_for(executor: SingleThreadedExecutor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def _rig(ros_context) -> tuple[Receiver, Node, SingleThreadedExecutor]:
    """A receiver that acknowledges frames, a plain node to replay through, and an executor spinning both."""
    receiver = Receiver(context=ros_context)
    driver = Node("replay", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(receiver)
    executor.add_node(driver)
    return receiver, driver, executor


def _expected_bytes(images: list[dict], cam: str) -> list[bytes]:
    return [frame[cam].tobytes() for frame in images]


def test_lockstep_delivers_every_frame_once_in_order_with_bytes(ros_context, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    stamps, images = make_bag(bag, frames=8)
    receiver = Receiver(context=ros_context)
    node = ReplayNode(context=ros_context, parameter_overrides=[
        Parameter("bag", value=str(bag)), Parameter("lockstep", value=True),
        Parameter("wait_for_subscribers", value=5.0), Parameter("ack_timeout", value=10.0),
    ])
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(receiver)
    executor.add_node(node)
    try:
        summary = run_replay(executor, node.replayer)
        _spin_for(executor, 0.2)
        assert summary.stopped is None, summary.lines()
        assert summary.frames == 8 and summary.acks == 8
        for cam in CAMERAS:
            assert [s for s, _ in receiver.images[cam]] == stamps, cam
            assert [b for _, b in receiver.images[cam]] == _expected_bytes(images, cam)
        assert receiver.infos == stamps
        assert receiver.texts == ["start: {frame: 0, position: [0, 0], heading: 0}"]
        assert summary.published["/awalker/ground_truth"] == 8
        # The camera pose is latched: a subscriber that joins after the replay still gets it.
        from geometry_msgs.msg import PoseStamped

        late = Node("late", context=ros_context)
        poses: list = []
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        late.create_subscription(PoseStamped, "/cam1/camera_pose", poses.append, latched)
        executor.add_node(late)
        deadline = time.monotonic() + 5
        while not poses and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        with SequenceReader(bag) as reader:
            cam1 = reader.cameras[1]
        assert len(poses) == 1 and poses[0].header.frame_id == "world"
        p = poses[0].pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], cam1.position)
        q = poses[0].pose.orientation
        np.testing.assert_allclose(np.abs(np.dot([q.x, q.y, q.z, q.w], cam1.quaternion)), 1.0, atol=1e-9)
    finally:
        executor.shutdown()
        node.destroy_node()
        receiver.destroy_node()


def test_rate_mode_delivers_all_frames_at_the_scaled_rate(ros_context, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    stamps, images = make_bag(bag, frames=10, compressed=True)
    receiver = Receiver(compressed=True, ack=False, context=ros_context)
    replay_node = Node("replay", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(receiver)
    executor.add_node(replay_node)
    rate = 2.0
    try:
        announced: list[int] = []
        replayer = Replayer(replay_node, bag, ReplayConfig(rate=rate, wait_for_subscribers=5.0),
                            on_frame=announced.append)
        summary = run_replay(executor, replayer)
        assert announced == stamps
        _spin_for(executor, 0.3)
        assert summary.stopped is None and summary.frames == 10 and summary.acks == 0
        with SequenceReader(bag) as reader:
            raw = {cam: [bytes(m.data) for _, _, _, m in reader.messages([f"/{cam}/image_raw/compressed"])]
                   for cam in CAMERAS}
        for cam in CAMERAS:
            assert [s for s, _ in receiver.images[cam]] == stamps
            assert [b for _, b in receiver.images[cam]] == raw[cam]
        # Frames are paced: 9 periods of 33.3 ms at rate 2 take at least ~150 ms (lower bound only).
        paced = (stamps[-1] - stamps[0]) / 1e9 / rate
        assert summary.duration_s >= 0.9 * paced
    finally:
        executor.shutdown()


def test_lockstep_frames_ahead_keeps_that_many_frames_unacknowledged(ros_context, tmp_path: Path) -> None:
    """frames_ahead 2: three frames go out before the first ack, one more per ack, all in order."""
    from std_msgs.msg import Header

    bag = tmp_path / "bag"
    stamps, _ = make_bag(bag, frames=6)
    receiver = Receiver(ack=False, context=ros_context)
    driver = Node("replay", context=ros_context)
    acker = driver.create_publisher(Header, "/awalker/ack", 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(receiver)
    executor.add_node(driver)

    def ack(stamp_ns: int) -> None:
        msg = Header()
        msg.stamp.sec, msg.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        acker.publish(msg)

    def run_for(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and replayer.step():
            executor.spin_once(timeout_sec=replayer.next_wait())

    try:
        announced: list[int] = []
        replayer = Replayer(driver, bag, ReplayConfig(lockstep=True, frames_ahead=2, wait_for_subscribers=5.0,
                                                      ack_timeout=10.0), on_frame=announced.append)
        run_for(1.5)
        assert announced == stamps[:3]
        ack(stamps[0])
        run_for(0.5)
        assert announced == stamps[:4]
        ack(stamps[5])                      # acks are cumulative: the last frame's ack releases all
        run_for(2.0)
        assert replayer.done and replayer.summary.stopped is None and announced == stamps
        _spin_for(executor, 0.2)
        assert [s for s, _ in receiver.images["cam0"]] == stamps
    finally:
        executor.shutdown()
    for bad in (-1, 100):
        with pytest.raises(InputError, match="frames_ahead must lie in"):
            ReplayConfig(lockstep=True, frames_ahead=bad).validated("replay test")


def test_a_replay_through_the_callers_reader_leaves_it_open(ros_context, tmp_path: Path) -> None:
    """Replayer(reader=...) replays the bag through an open reader it was given and does not close it: the
    caller reads on and replays again through it (`awalker track` opens a bag once for all its passes)."""
    bag = tmp_path / "bag"
    stamps, images = make_bag(bag, frames=5)
    receiver, driver, executor = _rig(ros_context)
    config = ReplayConfig(lockstep=True, wait_for_subscribers=5.0, ack_timeout=10.0)
    try:
        with SequenceReader(bag) as sequence:
            for _ in range(2):
                summary = run_replay(executor, Replayer(driver, bag, config, reader=sequence.reader))
                assert summary.stopped is None and summary.frames == 5, summary.lines()
                assert sum(1 for _ in sequence.frames(decode=False)) == 5      # the reader is still open
        _spin_for(executor, 0.2)
        assert [s for s, _ in receiver.images["cam0"]] == stamps + stamps
        assert [b for _, b in receiver.images["cam0"]] == 2 * _expected_bytes(images, "cam0")
    finally:
        executor.shutdown()


def test_local_readers_start_the_replay_without_the_settle_time(ros_context, tmp_path: Path) -> None:
    """Readers in this process are known to have matched (both ends), so the replay starts at once and
    loses nothing; without ``local_nodes`` it sits out ``settle`` (here 1000 s) before the first message."""
    bag = tmp_path / "bag"
    stamps, images = make_bag(bag, frames=6)
    receiver, driver, executor = _rig(ros_context)
    config = ReplayConfig(lockstep=True, wait_for_subscribers=5.0, settle=1000.0, ack_timeout=10.0)
    try:
        waiting = Replayer(driver, bag, config)
        end = time.monotonic() + 1.0
        while time.monotonic() < end and waiting.step():
            executor.spin_once(timeout_sec=waiting.next_wait())
        assert not waiting.done and waiting.summary.published == {}
        waiting.close()
        replayer = Replayer(driver, bag, config, local_nodes=[receiver])
        summary = run_replay(executor, replayer)
        _spin_for(executor, 0.2)
        assert summary.stopped is None and summary.frames == 6 and summary.acks == 6
        for cam in CAMERAS:
            assert [b for _, b in receiver.images[cam]] == _expected_bytes(images, cam)
    finally:
        executor.shutdown()


class _Endpoint:
    def __init__(self, topic: str, matched: int) -> None:
        self.topic_name, self.matched = topic, matched

    def get_subscription_count(self) -> int:
        return self.matched

    get_publisher_count = get_subscription_count


class _Endpoints:
    def __init__(self, publishers: list[_Endpoint], subscriptions: list[_Endpoint]) -> None:
        self.publishers, self.subscriptions = publishers, subscriptions


def test_unmatched_local_topics_needs_both_ends_of_every_local_pair() -> None:
    # /a: one publisher, two local readers; /b: one pair; /only_pub and /only_sub: no local pair
    def nodes(pub_a: int, sub_a: tuple[int, int], pub_b: int, sub_b: int) -> list[_Endpoints]:
        return [_Endpoints([_Endpoint("/a", pub_a), _Endpoint("/b", pub_b), _Endpoint("/only_pub", 0)], []),
                _Endpoints([], [_Endpoint("/a", sub_a[0]), _Endpoint("/b", sub_b), _Endpoint("/only_sub", 0)]),
                _Endpoints([], [_Endpoint("/a", sub_a[1])])]

    assert unmatched_local_topics(nodes(2, (1, 1), 1, 1)) == []
    assert unmatched_local_topics(nodes(1, (1, 1), 1, 1)) == ["/a"]    # the writer saw one reader of two
    assert unmatched_local_topics(nodes(2, (1, 0), 1, 1)) == ["/a"]    # a reader has not matched the writer
    assert unmatched_local_topics(nodes(2, (1, 1), 1, 0)) == ["/b"]
    assert unmatched_local_topics(nodes(5, (3, 3), 1, 1)) == []        # readers in other processes count too


def test_topic_filter_and_ack_timeout(ros_context, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    make_bag(bag, frames=3)
    node = Node("replay", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        replayer = Replayer(node, bag, ReplayConfig(lockstep=True, topics=("/cam0/image_raw",),
                                                     wait_for_subscribers=0.0, ack_timeout=0.3))
        summary = run_replay(executor, replayer)
        assert summary.published == {"/cam0/image_raw": 1}
        assert summary.stopped is not None and "no ack on /awalker/ack" in summary.stopped
        assert "STOPPED" in summary.lines()[0]
    finally:
        executor.shutdown()


def test_bad_replay_inputs(ros_context, tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    make_bag(bag, frames=2)
    node = Node("replay", context=ros_context)
    with pytest.raises(InputError, match=r"--topics \['/nope'\] not in the bag"):
        Replayer(node, bag, ReplayConfig(topics=("/nope",)))
    with pytest.raises(InputError, match="lockstep needs camera image topics"):
        Replayer(node, bag, ReplayConfig(lockstep=True, topics=("/cam0/camera_info",)))
    with pytest.raises(InputError, match="rate must be > 0"):
        Replayer(node, bag, ReplayConfig(rate=0.0))
    with pytest.raises(InputError, match="bag not found"):
        Replayer(node, tmp_path / "missing", ReplayConfig())
    with pytest.raises(InputError, match="parameter 'bag' is required"):
        ReplayNode(context=ros_context)
    node.destroy_node()


def test_header_stamp_from_cdr_matches_deserialised_header() -> None:
    ts = typestore()
    types = ts.types
    msg = types["sensor_msgs/msg/Image"](
        types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](1_700_000_123, 456_789), "f"),
        1, 1, "mono8", 0, 1, np.array([5], np.uint8),
    )
    raw = ts.serialize_cdr(msg, "sensor_msgs/msg/Image")
    assert header_stamp_ns(raw) == 1_700_000_123_000_456_789
    big_endian = bytes([0, 0, 0, 0]) + struct.pack(">iI", 12, 34) + b"\0" * 8
    assert header_stamp_ns(big_endian) == 12_000_000_034
    with pytest.raises(ValueError):
        header_stamp_ns(b"\0\1\0\0")


def test_batches_group_each_frame_with_its_side_messages(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    stamps, _ = make_bag(bag, frames=4)
    reader = open_reader(bag)
    try:
        image_topics = {"/cam0/image_raw", "/cam1/image_raw"}
        batches: list[Batch] = list(iter_batches(iter_messages(reader, bag), image_topics))
    finally:
        reader.close()
    assert [b.stamp_ns for b in batches] == stamps
    first_topics = [c.topic for c, _ in batches[0].messages]
    assert first_topics[0] in ("/tf_static", "/awalker/start_description")
    for batch in batches:
        topics = [c.topic for c, _ in batch.messages]
        assert sorted(t for t in topics if t in image_topics) == sorted(image_topics)
        assert topics.count("/awalker/ground_truth") == 1
        assert topics.count("/cam0/camera_info") == 1
    assert batches[1].log_ns - batches[0].log_ns == FRAME_PERIOD_NS


def _fake(topic: str, stamp: int | None = None) -> tuple[object, int, bytes]:
    from types import SimpleNamespace

    raw = b"\x00\x01\x00\x00" + struct.pack("<iI", 0, stamp or 0) + b"\x00" * 8
    return SimpleNamespace(topic=topic), (stamp or 0) * 10, raw


def _layout(batches: list[Batch]) -> list[tuple[int | None, list[str]]]:
    return [(b.stamp_ns, [f"{c.topic}@{header_stamp_ns(r)}" for c, r in b.messages]) for b in batches]


def test_batches_reassemble_frames_interleaved_out_of_stamp_order() -> None:
    images = {"/c0/image_raw", "/c1/image_raw"}
    stream = [_fake("/tf_static", 1), _fake("/c0/image_raw", 1), _fake("/c0/camera_info", 1),
              _fake("/c0/image_raw", 2), _fake("/c1/image_raw", 1), _fake("/c1/camera_info", 1),
              _fake("/c1/image_raw", 2), _fake("/gt", 2), _fake("/c0/image_raw", 3), _fake("/c1/image_raw", 3)]
    assert _layout(list(iter_batches(iter(stream), images))) == [
        (1, ["/tf_static@1", "/c0/image_raw@1", "/c0/camera_info@1", "/c1/image_raw@1", "/c1/camera_info@1"]),
        (2, ["/c0/image_raw@2", "/c1/image_raw@2", "/gt@2"]),
        (3, ["/c0/image_raw@3", "/c1/image_raw@3"]),
    ]


def test_batches_emit_a_frame_a_camera_skipped_once_a_newer_frame_is_complete() -> None:
    images = {"/c0/image_raw", "/c1/image_raw"}
    stream = [_fake("/c0/image_raw", 1), _fake("/c1/image_raw", 1), _fake("/c0/image_raw", 2),
              _fake("/c0/image_raw", 3), _fake("/c1/image_raw", 3), _fake("/c0/image_raw", 4),
              _fake("/c1/image_raw", 4), _fake("/note", 9)]
    batches = list(iter_batches(iter(stream), images))
    assert [b.stamp_ns for b in batches] == [1, 2, 3, 4]
    assert _layout(batches)[1] == (2, ["/c0/image_raw@2"])
    assert _layout(batches)[3] == (4, ["/c0/image_raw@4", "/c1/image_raw@4", "/note@9"])
    no_images = list(iter_batches(iter([_fake("/a", 1), _fake("/b", 2)]), set()))
    assert [(b.stamp_ns, len(b.messages), b.log_ns) for b in no_images] == [(None, 1, 10), (None, 1, 20)]
