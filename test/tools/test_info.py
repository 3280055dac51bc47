"""`awalker info`: topics, counts, duration, cameras, and MISSING lines for what tracking needs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from awalker_tools import cli
from awalker_tools.bagio import BODY_DESCRIPTION_TOPIC, START_DESCRIPTION_TOPIC, STRING, SequenceWriter
from awalker_tools.typestore import typestore
from awalker_tracker.vision.camera import Camera
from rosbags.rosbag2 import Writer

CAMS = [
    Camera.look_at("cam0", 20, 10, 15.0, [3.0, 1.0, 1.5], [0.0, 0.0, 1.0]),
    Camera.look_at("side", 12, 8, 10.0, [0.0, -3.0, 2.0], [0.0, 0.0, 1.0]),
]


def complete_bag(path: Path, frames: int = 5) -> None:
    with SequenceWriter(path, CAMS, compressed=True) as writer:
        writer.write_text(START_DESCRIPTION_TOPIC, 1_000_000_000, "start: {}")
        writer.write_text(BODY_DESCRIPTION_TOPIC, 1_000_000_000, "body: {}")
        for i in range(frames):
            stamp = 1_000_000_000 + i * 50_000_000
            writer.write_frame(stamp, {c.name: np.zeros((c.height, c.width, 3), np.uint8) for c in CAMS})
            writer.write_ground_truth(stamp, np.zeros((13, 3)))


def test_complete_bag_reports_everything_and_nothing_missing(tmp_path: Path, capsys) -> None:
    bag = tmp_path / "ok"
    complete_bag(bag)
    assert cli.main(["info", str(bag), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["missing"] == []
    assert info["frames"] == 5 and info["storage"] == "mcap"
    assert abs(info["duration_s"] - 0.2) < 1e-9
    counts = {t["name"]: (t["type"], t["count"], t["latched"]) for t in info["topics"]}
    assert counts["/cam0/image_raw/compressed"] == ("sensor_msgs/msg/CompressedImage", 5, False)
    assert counts["/side/camera_info"] == ("sensor_msgs/msg/CameraInfo", 5, False)
    assert counts["/tf_static"] == ("tf2_msgs/msg/TFMessage", 1, True)
    assert counts[START_DESCRIPTION_TOPIC] == (STRING, 1, True)
    cams = {c["name"]: c for c in info["cameras"]}
    assert (cams["side"]["width"], cams["side"]["height"]) == (12, 8)
    np.testing.assert_allclose(cams["cam0"]["position"], [3.0, 1.0, 1.5])
    assert cli.main(["info", str(bag)]) == 0
    text = capsys.readouterr().out
    assert "MISSING" not in text and "ready for tracking" in text
    assert "side: 12x8, 5 frames on /side/image_raw/compressed at [0.000, -3.000, 2.000] m" in text


def test_missing_descriptions_are_listed(tmp_path: Path, capsys) -> None:
    bag = tmp_path / "nodesc"
    with SequenceWriter(bag, CAMS[:1], storage="sqlite3") as writer:
        writer.write_frame(7, {"cam0": np.zeros((10, 20, 3), np.uint8)})
    assert cli.main(["info", str(bag)]) == 0
    missing = [line for line in capsys.readouterr().out.splitlines() if line.startswith("MISSING")]
    assert len(missing) == 2
    assert any(START_DESCRIPTION_TOPIC in line for line in missing)
    assert any(BODY_DESCRIPTION_TOPIC in line for line in missing)


def test_bag_without_cameras_poses_or_images(tmp_path: Path, capsys) -> None:
    ts = typestore()
    bag = tmp_path / "bare"
    with Writer(bag, version=9) as raw:
        info_type = "sensor_msgs/msg/CameraInfo"
        conn = raw.add_connection("/cam0/camera_info", info_type, typestore=ts)
        types = ts.types
        header = types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](0, 1), "cam0_optical_frame")
        msg = types[info_type](header, 10, 20, "plumb_bob", np.zeros(5), np.array([15.0, 0, 9.5, 0, 15, 4.5, 0, 0, 1]),
                               np.eye(3).ravel(), np.zeros(12), 0, 0,
                               types["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False))
        raw.write(conn, 1, ts.serialize_cdr(msg, info_type))
    assert cli.main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    missing = [line for line in out.splitlines() if line.startswith("MISSING")]
    assert any("/cam0/image_raw" in line and "no images" in line for line in missing)
    assert any("/tf_static" in line and "camera poses" in line for line in missing)
    assert "cam0: 20x10, 0 frames" in out

    empty = tmp_path / "strings"
    with Writer(empty, version=9) as raw:
        conn = raw.add_connection("/chatter", STRING, typestore=ts)
        raw.write(conn, 5, ts.serialize_cdr(ts.types[STRING](data="x"), STRING))
    assert cli.main(["info", str(empty), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["cameras"] == [] and info["frames"] == 0
    assert any("no /<cam>/camera_info topic" in m for m in info["missing"])


def test_cameras_whose_stamps_do_not_pair_are_missing(tmp_path: Path, capsys) -> None:
    """A second camera 20 ms behind at 20 fps (more than a third of a 50 ms frame): `awalker track` refuses the
    bag, and info says why, with track's own words (pipeline.check_camera_sync); 3 ms behind pairs."""
    from bag_helpers import shift_camera

    complete_bag(tmp_path / "ok", frames=8)
    shift_camera(tmp_path / "ok", tmp_path / "apart20", "side", 20_000_000)
    assert cli.main(["info", str(tmp_path / "apart20")]) == 0
    missing = [line for line in capsys.readouterr().out.splitlines() if line.startswith("MISSING")]
    assert missing == ["MISSING: cameras out of sync: the images of /side/image_raw/compressed lie a median 20.0 ms "
                       "from the nearest of /cam0/image_raw/compressed, more than --sync-tolerance 0.333 of a 50.0 ms "
                       "frame; pass --sync-tolerance above 0.40 (below 1) to pair them"], missing
    shift_camera(tmp_path / "ok", tmp_path / "apart3", "side", 3_000_000)
    assert cli.main(["info", str(tmp_path / "apart3")]) == 0
    assert "ready for tracking: nothing missing" in capsys.readouterr().out
