"""Shared by the tracking tests: small synthetic walks, each test worker's own DDS domain, and bags copied
message for message with their camera images replaced."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest


@pytest.fixture(autouse=True)
def isolated_ros(monkeypatch, ros_domain_id: int) -> None:
    """`awalker track` runs its nodes in this process (or a child, which inherits the environment): keep parallel
    test workers apart. Autouse in every module that imports it."""
    monkeypatch.setenv("ROS_DOMAIN_ID", str(ros_domain_id + 30))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")


def synth_walk(tmp_path_factory, frames: int, background: int, *options: str) -> Path:
    """A 160x120 synthetic walk of ``frames`` frames with the person after ``background`` empty ones (``options``:
    more `awalker synth` options), from the first synth seed whose walker does not fall; its bag."""
    from awalker_tools.cli import main

    for seed in range(1, 15):
        out = tmp_path_factory.mktemp(f"synth{seed}")
        code = main(["synth", "--out", str(out), *options, "--frames", str(frames), "--background-frames",
                     str(background), "--size", "160", "120", "--seed", str(seed)])
        if code == 0:
            return out / "synth.bag"
    pytest.fail("awalker synth could not make a walk that does not fall")


def rewrite_images(source: Path, target: Path, image: Any) -> None:
    """``source`` copied to ``target`` message for message, each camera image replaced by ``image(rgb, msg)`` (a
    (topic suffix, message type, message) triple: the same camera, another encoding or format string)."""
    from rosbags.rosbag2 import Writer

    from awalker_tools.bagio import COMPRESSED_IMAGE, IMAGE, SequenceReader, iter_messages
    from awalker_tools.typestore import typestore
    from awalker_tracker.vision.decode import decode_image

    store = typestore()
    with SequenceReader(source) as reader, Writer(target, version=9) as writer:
        made: dict[str, Any] = {}
        for conn, stamp, raw in iter_messages(reader.reader, source, reader.reader.connections):
            topic, msgtype, msg = conn.topic, conn.msgtype, None
            if msgtype in (IMAGE, COMPRESSED_IMAGE) and "/image_raw" in topic:
                old = store.deserialize_cdr(raw, msgtype)
                suffix, msgtype, msg = image(decode_image(old, topic), old)
                topic = topic.split("/image_raw")[0] + "/image_raw" + suffix
            if topic not in made:
                made[topic] = writer.add_connection(topic, msgtype, typestore=store,
                                                    offered_qos_profiles=conn.ext.offered_qos_profiles)
            writer.write(made[topic], stamp, raw if msg is None else store.serialize_cdr(msg, msgtype))


def shift_camera(source: Path, target: Path, camera: str, offset_ns: int, drop_every: int = 0) -> None:
    """``source`` copied to ``target`` with camera ``camera``'s images and camera_info stamped (header and bag
    time) ``offset_ns`` later, and with ``drop_every`` > 0 its every ``drop_every``-th image (frames
    drop_every - 1, 2 drop_every - 1, ...) and camera_info left out."""
    import dataclasses

    from rosbags.rosbag2 import Writer

    from awalker_tools.bagio import SequenceReader, iter_messages
    from awalker_tools.typestore import typestore

    store = typestore()
    Time = store.types["builtin_interfaces/msg/Time"]
    counts: dict[str, int] = {}
    with SequenceReader(source) as reader, Writer(target, version=9) as writer:
        made: dict[str, Any] = {}
        for conn, stamp, raw in iter_messages(reader.reader, source, reader.reader.connections):
            if conn.topic.startswith(f"/{camera}/") and conn.topic.endswith(("/image_raw", "/compressed",
                                                                             "/camera_info")):
                k = counts[conn.topic] = counts.get(conn.topic, -1) + 1
                if drop_every and k % drop_every == drop_every - 1:
                    continue
                msg = store.deserialize_cdr(raw, conn.msgtype)
                shifted = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec + offset_ns
                header = dataclasses.replace(msg.header, stamp=Time(sec=shifted // 1_000_000_000,
                                                                    nanosec=shifted % 1_000_000_000))
                raw, stamp = store.serialize_cdr(dataclasses.replace(msg, header=header), conn.msgtype), stamp + offset_ns
            if conn.topic not in made:
                made[conn.topic] = writer.add_connection(conn.topic, conn.msgtype, typestore=store,
                                                         offered_qos_profiles=conn.ext.offered_qos_profiles)
            writer.write(made[conn.topic], stamp, raw)


def walks_bag(out: Path, walks: list[tuple[tuple[float, float], float, int, float]], camera_position: tuple[float, ...],
              camera_target: tuple[float, ...], size: tuple[int, int] = (320, 240), background: int = 30) -> Path:
    """A one-camera bag (``out``/synth.bag, calibration.yaml and ground_truth.csv beside it) of walks one after the
    other, each ((x, y) start m, heading rad, frames, speed m/s) a walker of its own (30 Hz), seen by a camera at
    ``camera_position`` looking at ``camera_target`` (world m); the truth is whoever walks at the frame."""
    import numpy as np

    from awalker_tools import synth
    from awalker_tracker.errors import InputError
    from awalker_tracker.model.body import BodySegments
    from awalker_tracker.vision.camera import Camera, save_calibration

    width, height = size
    camera = Camera.look_at("cam0", width, height, 0.82 * width, np.array(camera_position, float),
                            np.array(camera_target, float))
    rng = np.random.default_rng(1)
    motions = []
    for k, (xy, heading, frames, speed) in enumerate(walks):
        for seed in range(1, 15):
            try:
                config = synth.SynthConfig(out_dir=out, frames=frames, seed=seed + 10 * k, speed=speed,
                                           step_length=0.7 * (speed / 1.3) ** 0.42)
                motions.append(synth.walker_motion(config,
                                                   np.array(xy, float), heading, np.random.default_rng(seed + 10 * k)))
                break
            except InputError:       # that walker fell: the next seed
                continue
    first = motions[0]
    motion = synth.Motion(np.concatenate([m.markers for m in motions]),
                          BodySegments(np.concatenate([m.segments.origin for m in motions]),
                                       np.concatenate([m.segments.rotation for m in motions])),
                          first.body, np.concatenate([m.joint_angles for m in motions]), first.start)
    scene = synth.Scene([camera], [synth.render_room(camera, synth.make_textures(rng))])
    out.mkdir(parents=True, exist_ok=True)
    save_calibration([camera], out / "calibration.yaml")
    synth.write_sequence(out, "synth", motion, scene, synth.Lighting(change=0.0, noise_sigma=3.0), 30.0, background,
                         rng, progress=False)
    return out / "synth.bag"
