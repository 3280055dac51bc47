"""Shared by the tracking tests: a bag copied message for message with its camera images replaced."""
from __future__ import annotations

from pathlib import Path
from typing import Any


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
