"""Replay a bag into ROS 2: every topic with its stored type, reliable like a driver.

Two modes:

- rate mode: messages go out at their bag times scaled by ``rate`` (real-time factor);
- lockstep: one frame at a time (all messages up to and including the images of one frame: paired by
  nearest stamp within ``sync_tolerance`` of a frame period, as the tracker pairs them), then wait for an acknowledgement (std_msgs/Header on ``ack_topic`` whose stamp is the
  frame's image stamp) before the next frame, so offline processing drops nothing and is
  deterministic. ``frames_ahead`` lets that many further frames out before the oldest is
  acknowledged, so the feature nodes work on the next frame while the tracker works on this one.

Messages are published as their raw CDR bytes from the bag (``Publisher.publish(bytes)`` calls
``publish_raw``): no deserialisation, no copy into Python message objects. Latched topics
(``/tf_static``, the description strings, any topic the bag recorded as transient-local) are
published TRANSIENT_LOCAL. Because ``tf2_msgs`` is not installable from PyPI, the replay also
publishes each camera's pose from ``/tf_static`` as ``/<cam>/camera_pose``
(geometry_msgs/PoseStamped, parent ``world``, latched); ``/tf_static`` itself is published
when ``tf2_msgs`` imports (a full ROS install) and otherwise reported as skipped.

The core (``Replayer``) does not own an executor: a driver calls ``step()`` and spins its
executor for ``next_wait()`` seconds in between (``run_replay``), so ``awalker track`` can run
replay, feature and tracker nodes in one process and one executor.
"""
from __future__ import annotations

import importlib
import math
import struct
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader

from awalker_tracker.errors import InputError
from awalker_tracker.inference.sync import DEFAULT_TOLERANCE, StampSynchronizer
from awalker_tracker.nodes.base import AwalkerNode, NodeParameter, declare_parameters
from awalker_tracker.nodes.spin import run_node

from awalker_tools.bagio import (
    COMPRESSED_IMAGE,
    IMAGE,
    TF_STATIC_TOPIC,
    WORLD_FRAME,
    is_latched,
    iter_messages,
    open_reader,
)
from awalker_tools.typestore import typestore

DEFAULT_ACK_TOPIC = "/awalker/ack"
CAMERA_POSE_SUFFIX = "/camera_pose"
OPTICAL_SUFFIX = "_optical_frame"
PROGRESS_PERIOD_S = 5.0
ACK_FLUSH_TIMEOUT_S = 5.0  # at the end, wait this long at most for reliable readers to acknowledge


@dataclass(frozen=True)
class ReplayConfig:
    """Replay settings. Times in seconds."""

    rate: float = 1.0                   # real-time factor in rate mode (2.0 = twice as fast)
    lockstep: bool = False              # wait for an ack of each frame before the next
    ack_topic: str = DEFAULT_ACK_TOPIC  # std_msgs/Header, stamp = acknowledged frame stamp
    topics: tuple[str, ...] = ()        # replay only these topics (empty: all)
    wait_for_subscribers: float = 10.0  # s to wait for subscribers before the first message (0: no wait)
    settle: float = 0.5                 # s to wait after the subscribers matched (discovery is asymmetric)
    ack_timeout: float = 60.0           # s to wait for one ack before giving up (lockstep)
    frames_ahead: int = 0               # lockstep: frames published beyond the oldest unacknowledged one
    sync_tolerance: float = DEFAULT_TOLERANCE   # frame periods: images nearer in stamp make one frame (0: equal)
    depth: int = 100                    # history depth of the volatile publishers (reliable)

    def validated(self, where: str) -> "ReplayConfig":
        if not self.rate > 0:
            raise InputError(f"{where}: rate must be > 0 (real-time factor), got {self.rate}")
        if not math.isfinite(self.rate):
            raise InputError(f"{where}: rate must be finite, got {self.rate}")
        if not all(math.isfinite(v) for v in (self.wait_for_subscribers, self.settle, self.ack_timeout)):
            raise InputError(f"{where}: ack_timeout, wait_for_subscribers and settle must be finite seconds, got "
                             f"{self.ack_timeout}, {self.wait_for_subscribers}, {self.settle}")
        if self.wait_for_subscribers < 0 or self.settle < 0 or self.ack_timeout <= 0 or self.depth < 1:
            raise InputError(f"{where}: wait_for_subscribers >= 0, settle >= 0, ack_timeout > 0 and depth >= 1 "
                             "expected")
        if not 0.0 <= self.sync_tolerance < 1.0:
            raise InputError(f"{where}: sync_tolerance must lie in [0, 1) frame periods, got {self.sync_tolerance}")
        if not 0 <= self.frames_ahead < self.depth:
            raise InputError(f"{where}: frames_ahead must lie in [0, depth = {self.depth}), got {self.frames_ahead}")
        return self


@dataclass
class ReplaySummary:
    """What a replay did."""

    bag: str
    published: dict[str, int] = field(default_factory=dict)  # topic -> messages
    skipped_topics: dict[str, str] = field(default_factory=dict)  # topic -> reason
    frames: int = 0
    acks: int = 0
    duration_s: float = 0.0
    stopped: str | None = None  # why the replay stopped early, None if complete

    def lines(self) -> list[str]:
        status = "complete" if self.stopped is None else f"STOPPED: {self.stopped}"
        out = [f"replay {self.bag}: {status}; {self.frames} frames, {sum(self.published.values())} messages, "
               f"{self.acks} acks in {self.duration_s:.2f} s"]
        for topic in sorted(self.published):
            out.append(f"  {topic}: {self.published[topic]}")
        for topic in sorted(self.skipped_topics):
            out.append(f"  skipped {topic}: {self.skipped_topics[topic]}")
        return out


@dataclass(frozen=True)
class Batch:
    """Messages published together: a frame's messages in bag order. Stamps in ns."""

    log_ns: int                      # bag time of the first message
    stamp_ns: int | None             # image header stamp of the frame (None: no image in the batch)
    messages: tuple[tuple[Connection, bytes], ...]


def header_stamp_ns(raw: bytes | memoryview) -> int:
    """Stamp of a CDR-serialised message whose first field is std_msgs/Header (ns)."""
    if len(raw) < 12:
        raise ValueError("serialised message shorter than a CDR header")
    little = raw[1] & 1  # encapsulation id 0x0001 = CDR little endian, 0x0000 = big endian
    sec, nanosec = struct.unpack_from("<iI" if little else ">iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


def is_camera_image_topic(topic: str, msgtype: str) -> bool:
    """Topics that define frames: ``/<cam>/image_raw`` (Image) and ``/<cam>/image_raw/compressed``."""
    return (msgtype == IMAGE and topic.endswith("/image_raw")) or (
        msgtype == COMPRESSED_IMAGE and topic.endswith("/image_raw/compressed"))


def iter_batches(
    messages: Iterator[tuple[Connection, int, bytes]], image_topics: set[str], tolerance: float = DEFAULT_TOLERANCE
) -> Iterator[Batch]:
    """Group bag messages into frames (batches), in stamp order.

    The images (of ``image_topics``) are paired into frames by nearest stamp, as the tracker pairs their
    features (``inference.sync.StampSynchronizer``, ``tolerance`` in frame periods: cameras whose stamps
    differ by less make one frame; a frame a camera skipped holds the others). Other messages join the
    frame of the latest image before them (messages before the first image join the first frame). A frame
    is emitted once a newer image has arrived after it is decided, with its messages in bag order; its
    stamp is its earliest image's (the tracker acknowledges a frame with its latest). So camera streams
    interleaved out of stamp order in the bag (recorded with receive times) still give whole frames.
    Without image topics every message is its own batch.
    """
    if not image_topics:
        for conn, log_ns, raw in messages:
            yield Batch(log_ns, None, ((conn, bytes(raw)),))
        return
    sync = StampSynchronizer(sorted(image_topics), max_pending=1_000_000, tolerance=tolerance)
    side: dict[int, list[tuple[int, int, Connection, bytes]]] = {}    # image stamp -> messages after it
    held: list[tuple[int, list[tuple[int, int, Connection, bytes]]]] = []   # decided frames: (stamp, messages)
    latest: int | None = None    # stamp of the latest image: the key of the messages after it
    held_stamps: dict[int, int] = {}    # image stamp of a held frame -> index in ``held``

    def batch(stamp: int, msgs: list[tuple[int, int, Connection, bytes]]) -> Batch:
        msgs.sort(key=lambda m: m[0])
        return Batch(msgs[0][1], stamp, tuple((conn, raw) for _, _, conn, raw in msgs))

    def decide(frames: list[Any]) -> None:
        for frame in frames:
            msgs = [item for item in frame.items if item is not None]
            for stamp in frame.stamps:
                if stamp is not None:
                    msgs += side.pop(stamp, [])
                    held_stamps[stamp] = len(held)
            held.append((min(s for s in frame.stamps if s is not None), msgs))

    first: list[tuple[int, int, Connection, bytes]] = []    # messages before the first image
    for seq, (conn, log_ns, raw) in enumerate(messages):
        message = (seq, log_ns, conn, bytes(raw))
        if conn.topic in image_topics:
            stamp = header_stamp_ns(message[3])
            frames, issues = sync.add(conn.topic, stamp, message)     # (the tracker reports the issues)
            # an image refused (a late or repeated stamp) goes out like the messages beside it
            if not any(i.kind in ("duplicate", "out_of_order") for i in issues):
                for held_stamp, msgs in held:
                    yield batch(held_stamp, msgs)
                held.clear()
                held_stamps.clear()
                latest = stamp
                if first:
                    side.setdefault(latest, []).extend(first)
                    first = []
                decide(frames)
                continue
        if latest is None:
            first.append(message)
        elif latest in held_stamps:
            held[held_stamps[latest]][1].append(message)
        else:
            side.setdefault(latest, []).append(message)
    decide(sync.flush()[0])
    for stamp, msgs in held:
        yield batch(stamp, msgs)
    leftover = [m for msgs in side.values() for m in msgs] + first
    if leftover:  # messages whose image was refused (a late or duplicate stamp), or no image at all
        leftover.sort(key=lambda m: m[0])
        yield Batch(leftover[0][1], None, tuple((conn, raw) for _, _, conn, raw in leftover))


def message_class(msgtype: str) -> type:
    """The rclpy message class for 'pkg/msg/Name'; ImportError/AttributeError if not installed."""
    package, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def camera_pose_topic(cam: str) -> str:
    return f"/{cam}{CAMERA_POSE_SUFFIX}"


def _qos(latched: bool, depth: int) -> QoSProfile:
    if latched:
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def unmatched_local_topics(nodes: Sequence[Node]) -> list[str]:
    """Topics on which a publisher and a subscription of ``nodes`` (one process) have not yet matched
    each other at both ends. A reader that has not matched a writer drops what it sends, and the writer
    side matches first, so each subscription must count every local publisher of its topic and each
    publisher every local subscription."""
    publishers: dict[str, list[Any]] = {}
    subscriptions: dict[str, list[Any]] = {}
    for node in nodes:
        for pub in node.publishers:
            publishers.setdefault(pub.topic_name, []).append(pub)
        for sub in node.subscriptions:
            subscriptions.setdefault(sub.topic_name, []).append(sub)
    waiting = []
    for topic in sorted(publishers.keys() & subscriptions.keys()):
        pubs, subs = publishers[topic], subscriptions[topic]
        if (any(p.get_subscription_count() < len(subs) for p in pubs)
                or any(s.get_publisher_count() < len(pubs) for s in subs)):
            waiting.append(topic)
    return waiting


class Replayer:
    """Publishes a bag through ``node``; drive it with ``step()`` / ``next_wait()`` (see run_replay)."""

    def __init__(
        self,
        node: Node,
        bag_path: str | Path,
        config: ReplayConfig = ReplayConfig(),
        on_frame: Callable[[int], None] | None = None,
        local_nodes: Sequence[Node] = (),
        reader: Reader | None = None,
    ) -> None:
        """``on_frame(stamp_ns)`` is called right after each frame's messages were published.
        ``local_nodes``: the nodes of this process that the replay feeds (they may also talk among
        themselves). With them, the replay starts as soon as every publisher-subscription pair among
        them and ``node`` has matched at both ends (``unmatched_local_topics``), without the
        ``settle`` time that readers in other processes need. ``reader``: an open reader of the bag (its owner
        closes it), else the replayer opens one."""
        self.node = node
        self._on_frame = on_frame
        self._local_nodes = [node, *[n for n in local_nodes if n is not node]] if local_nodes else []
        self.path = Path(bag_path)
        self.config = config.validated(f"replay {self.path}")
        self.summary = ReplaySummary(str(self.path))
        self._owns_reader = reader is None        # (opening a bag parses its metadata: ~30 ms)
        self._reader = open_reader(self.path) if reader is None else reader
        self._batches: Iterator[Batch] | None = None
        try:
            self._setup()
        except BaseException:
            self._release()
            raise

    # -- set-up -------------------------------------------------------------------------------
    def _setup(self) -> None:
        cfg = self.config
        connections = self._reader.connections
        bag_topics = {c.topic for c in connections}
        derived = self._derived_pose_topics(connections)
        wanted = set(cfg.topics)
        unknown = wanted - bag_topics - set(derived)
        if unknown:
            raise InputError(f"{self.path}: --topics {sorted(unknown)} not in the bag; "
                             f"bag topics are {sorted(bag_topics)}")
        selected = [c for c in connections if not wanted or c.topic in wanted]
        self._pose_topics = [t for t in derived if not wanted or t in wanted or TF_STATIC_TOPIC in wanted]
        self._publishers: dict[int, Any] = {}
        self._latched_counts: dict[str, int] = {}
        for conn in connections:
            if is_latched(conn):
                self._latched_counts[conn.topic] = self._latched_counts.get(conn.topic, 0) + conn.msgcount
        read: list[Connection] = []
        for conn in selected:
            try:
                cls = message_class(conn.msgtype)
            except (ImportError, AttributeError, ValueError):
                self.summary.skipped_topics[conn.topic] = f"message type {conn.msgtype} not installed for rclpy"
                if conn.topic == TF_STATIC_TOPIC and self._pose_topics:
                    read.append(conn)  # still read: camera poses are derived from it
                continue
            latched = is_latched(conn)
            depth = max(1, self._latched_counts.get(conn.topic, 1)) if latched else cfg.depth
            self._publishers[conn.id] = self.node.create_publisher(cls, conn.topic, _qos(latched, depth))
            read.append(conn)
        self._tf_static_ids = {c.id for c in read if c.topic == TF_STATIC_TOPIC}
        if self._pose_topics:
            from geometry_msgs.msg import PoseStamped

            self._pose_publishers = {
                t: self.node.create_publisher(PoseStamped, t, _qos(True, 1)) for t in self._pose_topics
            }
        else:
            self._pose_publishers = {}
        self._image_topics = {c.topic for c in read if is_camera_image_topic(c.topic, c.msgtype)}
        if cfg.lockstep and not self._image_topics:
            raise InputError(f"{self.path}: lockstep needs camera image topics (/<cam>/image_raw {IMAGE} or "
                             f"/<cam>/image_raw/compressed {COMPRESSED_IMAGE}) to define frames; selected topics "
                             f"are {sorted(c.topic for c in selected)}")
        self._ack_sub = None
        self._acked_stamp = -1
        if cfg.lockstep:
            from std_msgs.msg import Header

            self._ack_sub = self.node.create_subscription(
                Header, cfg.ack_topic, self._on_ack, _qos(False, max(cfg.depth, 10))
            )
        self._batches = iter_batches(iter_messages(self._reader, self.path, read), self._image_topics,
                                     cfg.sync_tolerance)
        self._next: Batch | None = None
        self._exhausted = False
        self._awaiting: deque[tuple[int, float]] = deque()   # (frame stamp ns, published at) not yet acked
        self._started = time.monotonic()
        self._subscribers_ok = cfg.wait_for_subscribers == 0
        self._matched_at: float | None = None
        self._t0_wall: float | None = None
        self._t0_bag: int | None = None
        self._last_progress = self._started
        self.done = False

    def _derived_pose_topics(self, connections: list[Connection]) -> list[str]:
        """``/<cam>/camera_pose`` for every camera with a camera_info topic, unless the bag has it."""
        names = {c.topic for c in connections}
        if TF_STATIC_TOPIC not in names:
            return []
        cams = sorted(t[1: -len("/camera_info")] for t in names if t.endswith("/camera_info") and t.count("/") == 2)
        return [camera_pose_topic(c) for c in cams if camera_pose_topic(c) not in names]

    def _on_ack(self, msg: Any) -> None:
        self.summary.acks += 1
        stamp = msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec
        self._acked_stamp = max(self._acked_stamp, stamp)

    # -- driving ------------------------------------------------------------------------------
    def _subscribers_matched(self) -> tuple[bool, list[str]]:
        """True when every image topic (else every topic) has a subscriber and, in lockstep, an ack publisher."""
        pubs = {p.topic_name: p for p in self._publishers.values()}
        pubs.update(self._pose_publishers)
        watch = [t for t in pubs if t in self._image_topics] or list(pubs)
        waiting = [t for t in watch if pubs[t].get_subscription_count() == 0]
        if self._ack_sub is not None and self._ack_sub.get_publisher_count() == 0:
            waiting.append(f"{self.config.ack_topic} (ack publisher)")
        return not waiting, waiting

    def next_wait(self) -> float:
        """Seconds the driver may spin before the next ``step()`` is useful."""
        if self.done:
            return 0.0
        if not self._subscribers_ok or self._must_wait():
            return 0.02
        if self._next is not None and self._t0_wall is not None and not self.config.lockstep:
            due = self._t0_wall + (self._next.log_ns - self._t0_bag) / 1e9 / self.config.rate  # type: ignore[operator]
            return max(0.0, min(0.1, due - time.monotonic()))
        return 0.0

    def _finish(self, stopped: str | None = None) -> None:
        self.done = True
        if stopped is None:  # let reliable readers receive the tail before publishers may be destroyed
            deadline = time.monotonic() + ACK_FLUSH_TIMEOUT_S
            for pub in [*self._publishers.values(), *self._pose_publishers.values()]:
                remaining = max(0.0, deadline - time.monotonic())
                pub.wait_for_all_acked(Duration(nanoseconds=int(remaining * 1e9)))
        self.summary.stopped = stopped
        self.summary.duration_s = time.monotonic() - self._started
        self._release()

    def _release(self) -> None:
        """End the reading of the bag's messages (a replay stopped early leaves none half read in the reader),
        and close the reader if this replayer opened it."""
        if self._batches is not None:
            self._batches.close()
        if self._owns_reader:
            self._reader.close()

    def step(self) -> bool:
        """Publish what is due now; False once the replay is over (``summary`` then final)."""
        if self.done:
            return False
        now = time.monotonic()
        cfg = self.config
        if not self._subscribers_ok:
            # A publisher sees its reader before the reader has matched the writer; messages sent in
            # between are lost, so wait ``settle`` seconds after the match.
            if self._matched_at is None:
                ok, waiting = self._subscribers_matched()
                if ok and self._local_nodes:
                    waiting = unmatched_local_topics(self._local_nodes)
                    ok = not waiting
                if ok:
                    self._matched_at = now
                elif now - self._started < cfg.wait_for_subscribers:
                    return True
                else:
                    self.node.get_logger().warning(
                        f"no subscriber after {cfg.wait_for_subscribers:.1f} s on {', '.join(waiting)}; "
                        "replaying anyway")
                    self._matched_at = now - cfg.settle
            if not self._local_nodes and now - self._matched_at < cfg.settle:
                return True
            self._subscribers_ok = True
        while True:
            while self._awaiting and self._acked_stamp >= self._awaiting[0][0]:
                self._awaiting.popleft()
            if self._next is None and not self._exhausted:
                self._next = next(self._batches, None)
                self._exhausted = self._next is None
            if self._must_wait():
                stamp, since = self._awaiting[0]
                if time.monotonic() - since > cfg.ack_timeout:
                    self._finish(f"no ack on {cfg.ack_topic} for frame {stamp} ns within {cfg.ack_timeout} s")
                    return False
                return True
            if self._exhausted:
                self._finish()
                return False
            batch = self._next
            assert batch is not None
            if not cfg.lockstep:
                if self._t0_wall is None:
                    self._t0_wall, self._t0_bag = time.monotonic(), batch.log_ns
                due = self._t0_wall + (batch.log_ns - self._t0_bag) / 1e9 / cfg.rate  # type: ignore[operator]
                if time.monotonic() < due:
                    return True
            self._publish(batch)
            self._next = None
            if cfg.lockstep and batch.stamp_ns is not None:
                self._awaiting.append((batch.stamp_ns, time.monotonic()))
            self._progress()

    def _must_wait(self) -> bool:
        """Lockstep: too many frames unacknowledged, or the bag is done and some still are."""
        return bool(self.config.lockstep and self._awaiting
                    and (self._exhausted or len(self._awaiting) > self.config.frames_ahead))

    def _publish(self, batch: Batch) -> None:
        published = self.summary.published
        for conn, raw in batch.messages:
            pub = self._publishers.get(conn.id)
            if pub is not None:
                pub.publish(raw)
                published[conn.topic] = published.get(conn.topic, 0) + 1
            if conn.id in self._tf_static_ids:
                self._publish_camera_poses(raw)
        if batch.stamp_ns is not None:
            self.summary.frames += 1
            if self._on_frame is not None:
                self._on_frame(batch.stamp_ns)

    def _publish_camera_poses(self, raw: bytes) -> None:
        from geometry_msgs.msg import PoseStamped

        tf_msg = typestore().deserialize_cdr(raw, "tf2_msgs/msg/TFMessage")
        for tf in tf_msg.transforms:
            child = tf.child_frame_id.lstrip("/")
            if tf.header.frame_id.lstrip("/") != WORLD_FRAME or not child.endswith(OPTICAL_SUFFIX):
                continue
            topic = camera_pose_topic(child[: -len(OPTICAL_SUFFIX)])
            pub = self._pose_publishers.get(topic)
            if pub is None:
                continue
            pose = PoseStamped()
            pose.header.stamp.sec, pose.header.stamp.nanosec = int(tf.header.stamp.sec), int(tf.header.stamp.nanosec)
            pose.header.frame_id = WORLD_FRAME
            t, q = tf.transform.translation, tf.transform.rotation
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = float(t.x), float(t.y), float(t.z)
            o = pose.pose.orientation
            o.x, o.y, o.z, o.w = float(q.x), float(q.y), float(q.z), float(q.w)
            pub.publish(pose)
            self.summary.published[topic] = self.summary.published.get(topic, 0) + 1

    def _progress(self) -> None:
        now = time.monotonic()
        if now - self._last_progress >= PROGRESS_PERIOD_S:
            self._last_progress = now
            print(f"replay {self.path.name}: {self.summary.frames} frames, "
                  f"{sum(self.summary.published.values())} messages, {now - self._started:.1f} s", file=sys.stderr)

    def close(self) -> None:
        """Stop early (e.g. on Ctrl-C) and release the bag."""
        if not self.done:
            self._finish("interrupted")


def run_replay(executor: Any, replayer: Replayer) -> ReplaySummary:
    """Drive ``replayer`` to the end, spinning ``executor`` (which must hold its node) in between."""
    try:
        while replayer.step():
            executor.spin_once(timeout_sec=replayer.next_wait())
    finally:
        replayer.close()
    return replayer.summary


# ---------------------------------------------------------------------------------------------
# The node and its console script
# ---------------------------------------------------------------------------------------------
_DEFAULTS = ReplayConfig()
#: The node's ROS parameters (declared from here; listed by ``awalker_replay --help``).
PARAMETERS = (
    NodeParameter("bag", "", "path of the rosbag2 bag to replay (directory, .mcap or .db3; required)"),
    NodeParameter("rate", _DEFAULTS.rate, "real-time factor in rate mode"),
    NodeParameter("lockstep", _DEFAULTS.lockstep, "wait for an ack of each frame before the next"),
    NodeParameter("ack_topic", _DEFAULTS.ack_topic, "std_msgs/Header acks carrying the frame stamp"),
    NodeParameter("topics", Parameter.Type.STRING_ARRAY, "replay only these topics (unset: all)"),
    NodeParameter("wait_for_subscribers", _DEFAULTS.wait_for_subscribers,
                  "seconds to wait for subscribers before the first message (0: no wait)"),
    NodeParameter("ack_timeout", _DEFAULTS.ack_timeout, "seconds to wait for one ack in lockstep"),
    NodeParameter("frames_ahead", _DEFAULTS.frames_ahead, "lockstep: frames published beyond the oldest unacknowledged one"),
    NodeParameter("sync_tolerance", _DEFAULTS.sync_tolerance, "images whose stamps differ by less than this fraction "
                  "of a frame make one frame (0: equal stamps only)"),
)


class ReplayNode(AwalkerNode):
    """rclpy node replaying the bag given by parameter ``bag`` (see ReplayConfig for the others)."""

    def __init__(self, node_name: str = "awalker_replay", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        values = declare_parameters(self, PARAMETERS)
        bag, rate, lockstep, ack_topic, topics, wait, ack_timeout, frames_ahead, tolerance = (
            values[p.name] for p in PARAMETERS)
        if not bag:
            raise InputError("parameter 'bag' is required (--ros-args -p bag:=PATH)")
        config = ReplayConfig(
            rate=float(rate), lockstep=bool(lockstep), ack_topic=str(ack_topic), topics=tuple(topics or ()),
            wait_for_subscribers=float(wait), ack_timeout=float(ack_timeout), frames_ahead=int(frames_ahead),
            sync_tolerance=float(tolerance),
        )
        self.replayer = Replayer(self, bag, config)


def replay_main(bag: str, config: ReplayConfig, args: list[str] | None = None) -> int:
    """Replay ``bag`` in a fresh default context; print the summary. 0 if complete, 1 if stopped early."""
    rclpy.init(args=args)
    node = None
    try:
        node = ReplayNode(parameter_overrides=[
            Parameter("bag", value=str(bag)), Parameter("rate", value=float(config.rate)),
            Parameter("lockstep", value=bool(config.lockstep)), Parameter("ack_topic", value=config.ack_topic),
            Parameter("wait_for_subscribers", value=float(config.wait_for_subscribers)),
            Parameter("ack_timeout", value=float(config.ack_timeout)),
            Parameter("frames_ahead", value=int(config.frames_ahead)),
            Parameter("sync_tolerance", value=float(config.sync_tolerance)),
            *([Parameter("topics", value=list(config.topics))] if config.topics else []),
        ])
        return _spin_replay(node)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def _spin_replay(node: ReplayNode) -> int:
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        summary = run_replay(executor, node.replayer)
    except (KeyboardInterrupt, ExternalShutdownException):
        summary = node.replayer.summary
    finally:
        executor.shutdown()
    for line in summary.lines():
        print(line)
    return 0 if summary.stopped is None else 1


def main(args: list[str] | None = None) -> int:
    """Console script ``awalker_replay --ros-args -p bag:=PATH [-p lockstep:=true] ...``."""
    return run_node("awalker_replay", ReplayNode, args, spin=_spin_replay, parameters=PARAMETERS,
                    summary="Publish a bag's topics into ROS 2, at a real-time factor or in lockstep with acks.")



if __name__ == "__main__":
    sys.exit(main())
