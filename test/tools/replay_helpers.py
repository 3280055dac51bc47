"""Shared by the replay tests: a small two-camera bag and a receiving node that acks frames."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from awalker_tools.bagio import SequenceWriter, START_DESCRIPTION_TOPIC
from awalker_tracker.vision.camera import Camera

CAMERAS = ("cam0", "cam1")
FRAME_PERIOD_NS = 33_333_333
FIRST_STAMP_NS = 1_700_000_000_000_000_000


def make_bag(
    path: Path, frames: int = 8, compressed: bool = False, storage: str = "mcap"
) -> tuple[list[int], list[dict]]:
    """A two-camera bag with random images; returns (stamps, images per frame)."""
    cams = [
        Camera.look_at("cam0", 32, 24, 30.0, [4.0, 0.0, 1.5], [0.0, 0.0, 1.0]),
        Camera.look_at("cam1", 20, 16, 20.0, [0.0, 4.0, 1.5], [0.0, 0.0, 1.0]),
    ]
    rng = np.random.default_rng(3)
    stamps = [FIRST_STAMP_NS + i * FRAME_PERIOD_NS for i in range(frames)]
    images = []
    with SequenceWriter(path, cams, storage=storage, compressed=compressed) as writer:
        writer.write_text(START_DESCRIPTION_TOPIC, stamps[0], "start: {frame: 0, position: [0, 0], heading: 0}")
        for stamp in stamps:
            frame = {c.name: rng.integers(0, 256, (c.height, c.width, 3), dtype=np.uint8) for c in cams}
            images.append(frame)
            writer.write_frame(stamp, frame)
            writer.write_ground_truth(stamp, rng.normal(size=(13, 3)))
    return stamps, images


def stamp_of(header: Any) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


class Receiver(Node):
    """Records images per camera (stamp, raw bytes) and acks a frame once every camera delivered it.

    Lockstep receivers use the sensor-data QoS (best effort, depth 5) like the feature nodes: one
    frame is in flight at a time. Rate-mode receivers must be reliable with a deep queue, or a
    busy process drops the oldest images (that is what best effort means).
    """

    def __init__(self, compressed: bool = False, ack: bool = True, **kwargs: Any) -> None:
        super().__init__("receiver", **kwargs)
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image
        from std_msgs.msg import Header, String

        self.images: dict[str, list[tuple[int, bytes]]] = {c: [] for c in CAMERAS}
        self.infos: list[int] = []
        self.texts: list[str] = []
        self._pending: dict[int, set[str]] = {}
        self.ack_pub = self.create_publisher(Header, "/awalker/ack", 10) if ack else None
        for cam in CAMERAS:
            if compressed:
                topic, msg_type = f"/{cam}/image_raw/compressed", CompressedImage
            else:
                topic, msg_type = f"/{cam}/image_raw", Image
            qos = qos_profile_sensor_data if ack else QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
            self.create_subscription(msg_type, topic, lambda m, cam=cam: self._on_image(cam, m), qos)
        self.create_subscription(CameraInfo, "/cam0/camera_info", lambda m: self.infos.append(stamp_of(m.header)), 50)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(String, START_DESCRIPTION_TOPIC, lambda m: self.texts.append(m.data), latched)

    def _on_image(self, cam: str, msg: Any) -> None:
        stamp = stamp_of(msg.header)
        self.images[cam].append((stamp, bytes(msg.data)))
        got = self._pending.setdefault(stamp, set())
        got.add(cam)
        if got == set(CAMERAS) and self.ack_pub is not None:
            del self._pending[stamp]
            self.ack_pub.publish(msg.header)
