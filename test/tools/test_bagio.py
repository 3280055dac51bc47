"""Sequence bags: write -> read back identical pixels, stamps, cameras; every bad input is an InputError."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from awalker_tools.bagio import (
    GROUND_TRUTH_TOPIC,
    START_DESCRIPTION_TOPIC,
    SequenceReader,
    SequenceWriter,
    torso_quaternion,
)
from awalker_tools.typestore import typestore
from awalker_tracker.errors import InputError
from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.vision.camera import Camera
from scipy.spatial.transform import Rotation


def two_cameras() -> list[Camera]:
    return [
        Camera.look_at("cam0", 40, 30, 35.0, [4.0, -1.0, 1.6], [0.0, 0.0, 1.0]),
        Camera.look_at("cam1", 24, 18, 20.0, [-1.0, 4.0, 2.0], [0.5, 0.0, 0.9],
                       distortion=[0.1, -0.02, 1e-3, 0.0, 5e-3]),
    ]


def write_sequence(path: Path, cameras: list[Camera], frames: int = 4, **kwargs) -> tuple[list[int], list[dict]]:
    rng = np.random.default_rng(7)
    stamps = [1_700_000_000_000_000_000 + i * 33_333_333 for i in range(frames)]
    images = []
    with SequenceWriter(path, cameras, **kwargs) as writer:
        writer.write_text(START_DESCRIPTION_TOPIC, stamps[0], "start: {frame: 0, position: [0, 0], heading: 0.0}")
        for stamp in stamps:
            frame = {c.name: rng.integers(0, 256, (c.height, c.width, 3), dtype=np.uint8) for c in cameras}
            images.append(frame)
            writer.write_frame(stamp, frame)
    return stamps, images


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("compressed", [False, True])
def test_round_trip_pixels_stamps_and_cameras(tmp_path: Path, storage: str, compressed: bool) -> None:
    cameras = two_cameras()
    bag = tmp_path / "seq"
    stamps, images = write_sequence(bag, cameras, storage=storage, compressed=compressed, image_format="png")
    with SequenceReader(bag) as reader:
        assert reader.camera_names == ["cam0", "cam1"]
        for got, want in zip(reader.cameras, cameras):
            assert (got.width, got.height) == (want.width, want.height)
            np.testing.assert_allclose(got.K, want.K)
            np.testing.assert_allclose(got.distortion, want.distortion)
            np.testing.assert_allclose(got.rotation, want.rotation, atol=1e-12)
            np.testing.assert_allclose(got.position, want.position)
        np.testing.assert_array_equal(reader.frame_stamps, stamps)
        frames = list(reader.frames())
        assert [s for s, _ in frames] == stamps
        for (_, got), want in zip(frames, images):
            for cam in want:
                assert got[cam].dtype == np.uint8
                np.testing.assert_array_equal(got[cam], want[cam])  # png is lossless
        assert reader.text(START_DESCRIPTION_TOPIC).startswith("start:")
        assert reader.text("/awalker/body_description") is None
        assert reader.ground_truth() is None


def test_jpeg_is_close_but_lossy(tmp_path: Path) -> None:
    cam = Camera.look_at("cam0", 64, 48, 50.0, [4.0, 0.0, 1.5], [0.0, 0.0, 1.0])
    smooth = np.zeros((48, 64, 3), np.uint8)
    smooth[..., 0] = np.linspace(0, 255, 64)[None, :]
    smooth[..., 1] = np.linspace(0, 255, 48)[:, None]
    smooth[..., 2] = 128
    with SequenceWriter(tmp_path / "j", [cam], compressed=True, image_format="jpeg") as writer:
        writer.write_frame(5, {"cam0": smooth})
    with SequenceReader(tmp_path / "j") as reader:
        (_, got), = list(reader.frames())
    err = np.abs(got["cam0"].astype(int) - smooth.astype(int))
    assert err.mean() < 4.0  # channel order kept (an RGB/BGR swap would give ~60)


def test_ground_truth_occlusion_masks_and_generic_messages(tmp_path: Path) -> None:
    cam = two_cameras()[0]
    rng = np.random.default_rng(1)
    markers = rng.normal(size=(3, 13, 3))
    masks = rng.random((3, cam.height, cam.width)) > 0.7
    with SequenceWriter(tmp_path / "gt", [cam], storage="sqlite3") as writer:
        for i in range(3):
            stamp = 10 + i
            writer.write_frame(stamp, {"cam0": np.zeros((cam.height, cam.width, 3), np.uint8)})
            writer.write_ground_truth(stamp, markers[i], ["left_knee"], [0.25 * i])
            writer.write_occlusion_mask(stamp, "cam0", masks[i])
        header = typestore().types["std_msgs/msg/Header"]
        time_type = typestore().types["builtin_interfaces/msg/Time"]
        writer.write_message("/awalker/ack", "std_msgs/msg/Header", 13, header(time_type(1, 2), "x"))
    with SequenceReader(tmp_path / "gt") as reader:
        stamps, got = reader.ground_truth()
        np.testing.assert_array_equal(stamps, [10, 11, 12])
        np.testing.assert_allclose(got, markers)
        occ = reader.occlusion_masks()
        np.testing.assert_array_equal(occ["cam0"][0], [10, 11, 12])
        np.testing.assert_array_equal(occ["cam0"][1], masks)
        assert reader.topics["/awalker/ack"] == "std_msgs/msg/Header"
        (_, _, _, gt_msg), *_ = list(reader.messages([GROUND_TRUTH_TOPIC]))
        assert list(gt_msg.marker_names) == list(MARKER_NAMES)
        assert list(gt_msg.joint_names) == ["left_knee"]


def test_torso_quaternion_recovers_a_known_rotation() -> None:
    rot = Rotation.from_euler("z", 0.7)
    markers = np.zeros((13, 3))
    markers[1] = [0, 0, 0.5]   # thorax above pelvis
    markers[3] = [0, 0.1, 0]   # left hip
    markers[4] = [0, -0.1, 0]  # right hip
    moved = rot.apply(markers) + [1.0, 2.0, 0.9]
    got = Rotation.from_quat(torso_quaternion(moved))
    assert (got * rot.inv()).magnitude() < 1e-9


def test_writer_rejects_bad_frames(tmp_path: Path) -> None:
    cameras = two_cameras()
    good = {c.name: np.zeros((c.height, c.width, 3), np.uint8) for c in cameras}
    with SequenceWriter(tmp_path / "w", cameras) as writer:
        writer.write_frame(100, good)
        with pytest.raises(InputError, match="increase strictly"):
            writer.write_frame(100, good)
        with pytest.raises(InputError, match="unknown \\['cam9'\\]"):
            writer.write_frame(200, {**good, "cam9": good["cam0"]})
        with pytest.raises(InputError, match="missing \\['cam1'\\]"):
            writer.write_frame(200, {"cam0": good["cam0"]})
        with pytest.raises(InputError, match="expected 40x30 pixels"):
            writer.write_frame(200, {**good, "cam0": np.zeros((31, 40, 3), np.uint8)})
        with pytest.raises(InputError, match="HxWx3 uint8"):
            writer.write_frame(200, {**good, "cam0": np.zeros((30, 40, 3), np.float32)})
        with pytest.raises(InputError, match="shape \\(13, 3\\)"):
            writer.write_ground_truth(200, np.zeros((12, 3)))
        with pytest.raises(InputError, match="unknown camera"):
            writer.write_occlusion_mask(200, "nope", np.zeros((30, 40)))
    with pytest.raises(InputError, match="exists already"):
        SequenceWriter(tmp_path / "w", cameras)
    with pytest.raises(InputError, match="storage must be"):
        SequenceWriter(tmp_path / "x", cameras, storage="rosbag1")


def test_writer_removes_partial_bag_on_error(tmp_path: Path) -> None:
    cam = two_cameras()[0]
    with pytest.raises(InputError):
        with SequenceWriter(tmp_path / "partial", [cam]) as writer:
            writer.write_frame(1, {"cam0": np.zeros((cam.height, cam.width, 3), np.uint8)})
            writer.write_frame(0, {"cam0": np.zeros((cam.height, cam.width, 3), np.uint8)})
    assert not (tmp_path / "partial").exists()


def test_missing_corrupt_and_truncated_bags(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="bag not found") as err:
        SequenceReader(tmp_path / "nope").__enter__()
    assert str(tmp_path / "nope") in str(err.value)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file at all" * 10)
    with pytest.raises(InputError, match="junk.mcap"):
        with SequenceReader(junk) as reader:
            list(reader.frames())
    empty_dir = tmp_path / "emptydir"
    empty_dir.mkdir()
    with pytest.raises(InputError, match="emptydir"):
        SequenceReader(empty_dir).__enter__()
    # Truncate the storage file of a valid bag: the reader must fail with the bag's name.
    cam = two_cameras()[0]
    bag = tmp_path / "trunc"
    write_sequence(bag, [cam], frames=6)
    (data,) = list(bag.glob("*.mcap"))
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    with pytest.raises(InputError, match="trunc"):
        with SequenceReader(bag) as reader:
            list(reader.frames())


def test_bag_without_camera_info_or_pose(tmp_path: Path) -> None:
    cam = two_cameras()[0]
    bag = tmp_path / "nocam"
    with SequenceWriter(bag, [cam]) as writer:
        writer.write_text(START_DESCRIPTION_TOPIC, 1, "start: {}")
    with SequenceReader(bag) as reader:
        with pytest.raises(InputError, match="cam0/camera_info holds no messages"):
            reader.cameras
    only_text = tmp_path / "textonly"
    from awalker_tools.bagio import STRING
    from rosbags.rosbag2 import Writer

    with Writer(only_text, version=9) as raw:
        conn = raw.add_connection("/note", STRING, typestore=typestore())
        raw.write(conn, 1, typestore().serialize_cdr(typestore().types[STRING](data="hi"), STRING))
    with SequenceReader(only_text) as reader:
        with pytest.raises(InputError, match=r"no camera found: expected /<cam>/camera_info"):
            reader.cameras


def test_a_bad_calibration_in_the_bag_names_the_bag_and_topic(tmp_path: Path) -> None:
    """The bag reader builds its cameras with the one validated builder (vision.camera.camera_from_info)."""
    good = two_cameras()[0]
    for name, cam, where, message in (
            ("nan_k", Camera(good.name, good.width, good.height, good.K * np.array([[np.nan, 1, 1], [1, 1, 1], [1, 1, 1]]),
                             good.distortion, good.rotation, good.position),
             "/cam0/camera_info: k", "NaN or infinity"),
            ("three_d", Camera(good.name, good.width, good.height, good.K, np.array([0.1, 0.0, 0.0]), good.rotation,
                               good.position),
             "/cam0/camera_info", "distortion model 'plumb_bob' takes 0 or 4 or 5 finite coefficients"),
            ("nan_position", Camera(good.name, good.width, good.height, good.K, good.distortion, good.rotation,
                                    np.array([np.nan, 0.0, 1.0])),
             "/tf_static (world -> cam0_optical_frame): position", "NaN or infinity")):
        bag = tmp_path / name
        write_sequence(bag, [cam], frames=1)
        with SequenceReader(bag) as reader:
            with pytest.raises(InputError) as err:
                reader.cameras
        assert str(err.value).startswith(f"{bag}: {where}: ") and message in str(err.value), str(err.value)


def test_typestore_hashes_match_rclpy_generated_types() -> None:
    import json
    import sys

    store = typestore()
    share = Path(sys.prefix) / "share" / "awalker_msgs" / "msg"
    checked = 0
    for path in share.glob("*.json"):
        want = json.loads(path.read_text())["type_hashes"][0]["hash_string"]
        assert store.hash_rihs01(f"awalker_msgs/msg/{path.stem}") == want, path.stem
        checked += 1
    assert checked >= 7
