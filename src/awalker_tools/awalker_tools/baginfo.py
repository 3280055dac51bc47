"""What a bag holds and what it lacks for tracking (``awalker info``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from awalker_tracker.errors import InputError
from awalker_tracker.inference.sync import DEFAULT_TOLERANCE
from awalker_tracker.vision.decode import UnsupportedEncoding

from awalker_tools.bagio import (
    BODY_DESCRIPTION_TOPIC,
    CAMERA_INFO,
    GROUND_TRUTH_TOPIC,
    START_DESCRIPTION_TOPIC,
    STRING,
    TF_STATIC_TOPIC,
    SequenceReader,
    camera_from_messages,
    camera_info_topic,
    is_latched,
)


def bag_info(path: str | Path) -> dict[str, Any]:
    """Topics, counts, duration, cameras and MISSING items of a bag, as plain data (JSON-ready); cameras whose
    stamps do not pair into frames within ``awalker track``'s default sync tolerance are a MISSING item."""
    from awalker_tools.pipeline import check_camera_sync

    path = Path(path)
    with SequenceReader(path) as seq:
        reader = seq.reader
        count = reader.message_count
        topics = [
            {"name": c.topic, "type": c.msgtype, "count": c.msgcount, "latched": is_latched(c)}
            for c in sorted(reader.connections, key=lambda c: c.topic)
        ]
        info: dict[str, Any] = {
            "path": str(path),
            "storage": _storage(path),
            "messages": count,
            "start_s": reader.start_time / 1e9 if count else None,
            "end_s": (reader.end_time - 1) / 1e9 if count else None,
            "duration_s": (reader.duration - 1) / 1e9 if count else 0.0,
            "topics": topics,
            "cameras": [],
            "missing": [],
            "notes": [],
        }
        missing: list[str] = info["missing"]
        names = seq.camera_names
        if not names:
            missing.append(f"cameras: no /<cam>/camera_info topic ({CAMERA_INFO})")
        transforms = seq.camera_transforms() if TF_STATIC_TOPIC in seq.topics else {}
        if names and TF_STATIC_TOPIC not in seq.topics:
            missing.append(f"{TF_STATIC_TOPIC}: no camera poses (tf2_msgs/TFMessage world -> <cam>_optical_frame)")
        counts = {t["name"]: t["count"] for t in topics}
        for name in names:
            entry: dict[str, Any] = {"name": name}
            image = seq.image_topic_of(name)
            entry["image_topic"] = image[0] if image else None
            entry["frames"] = counts[image[0]] if image else 0
            if image is None:
                missing.append(f"/{name}/image_raw: no images for camera {name} (Image or CompressedImage)")
            elif entry["frames"] == 0:
                missing.append(f"{image[0]}: topic holds no images")
            elif isinstance(error := seq.first_image_error(name), UnsupportedEncoding):
                missing.append(str(error))
            info_msg = seq.first_message(camera_info_topic(name))
            tf = transforms.get(f"{name}_optical_frame")
            if info_msg is None:
                missing.append(f"{camera_info_topic(name)}: topic holds no messages")
            else:
                entry.update(width=int(info_msg.width), height=int(info_msg.height))
            if tf is None and TF_STATIC_TOPIC in seq.topics:
                missing.append(f"{TF_STATIC_TOPIC}: no transform world -> {name}_optical_frame (camera pose)")
            if info_msg is not None and tf is not None:
                try:
                    cam = camera_from_messages(info_msg, tf, name)
                    entry.update(position=cam.position.tolist(), orientation=cam.quaternion.tolist(),
                                 fx=float(cam.K[0, 0]), fy=float(cam.K[1, 1]))
                except InputError as exc:
                    missing.append(f"camera {name}: invalid calibration ({exc})")
            info["cameras"].append(entry)
        if len(names) > 1 and all(c["frames"] for c in info["cameras"]):
            try:      # the cameras pair into frames as `awalker track` pairs them, or it refuses the bag
                check_camera_sync(path, seq, DEFAULT_TOLERANCE)
            except InputError as exc:
                missing.append(f"cameras out of sync: {str(exc).removeprefix(f'{path}: ')}")
        frame_counts = {c["frames"] for c in info["cameras"] if c["frames"]}
        if len(frame_counts) > 1:
            info["notes"].append(f"cameras have different frame counts {sorted(frame_counts)}")
        info["frames"] = min(frame_counts) if frame_counts else 0
        for topic, what in ((START_DESCRIPTION_TOPIC, "start description (initial position, heading, speed, "
                             "stance leg); or pass --start YAML to the tracker"),
                            (BODY_DESCRIPTION_TOPIC, "body description (segment lengths); or pass --body YAML")):
            if topic not in seq.topics:
                missing.append(f"{topic}: no {what}")
            elif seq.topics[topic] != STRING:
                missing.append(f"{topic}: holds {seq.topics[topic]}, expected {STRING}")
        if GROUND_TRUTH_TOPIC not in seq.topics:
            info["notes"].append(f"optional: no {GROUND_TRUTH_TOPIC} (needed only for evaluation)")
    return info


def _storage(path: Path) -> str:
    if path.is_file():
        return {".mcap": "mcap", ".db3": "sqlite3"}.get(path.suffix, path.suffix)
    if any(path.glob("*.mcap")):
        return "mcap"
    return "sqlite3" if any(path.glob("*.db3")) else "unknown"


def format_info(info: dict[str, Any]) -> str:
    """Human-readable report; one MISSING line per missing item."""
    lines = [f"bag:       {info['path']} ({info['storage']})"]
    if info["messages"]:
        lines.append(f"duration:  {info['duration_s']:.3f} s ({info['start_s']:.3f} .. {info['end_s']:.3f} s)")
    lines.append(f"messages:  {info['messages']}, frames: {info['frames']}")
    lines.append("topics:")
    width = max((len(t["name"]) for t in info["topics"]), default=0)
    for t in info["topics"]:
        latched = "  (latched)" if t["latched"] else ""
        lines.append(f"  {t['name']:<{width}}  {t['count']:>7}  {t['type']}{latched}")
    lines.append("cameras:" if info["cameras"] else "cameras:   none")
    for c in info["cameras"]:
        size = f"{c['width']}x{c['height']}" if "width" in c else "?x?"
        pose = ""
        if "position" in c:
            pose = " at [" + ", ".join(f"{v:.3f}" for v in c["position"]) + "] m, q [" + ", ".join(
                f"{v:.4f}" for v in c["orientation"]) + "]"
        lines.append(f"  {c['name']}: {size}, {c['frames']} frames on {c['image_topic']}{pose}")
    for note in info["notes"]:
        lines.append(f"note: {note}")
    for item in info["missing"]:
        lines.append(f"MISSING: {item}")
    if not info["missing"]:
        lines.append("ready for tracking: nothing missing")
    return "\n".join(lines)
