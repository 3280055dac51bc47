"""`awalker convert`: image folders and videos -> bag -> read back identical pixels and stamps."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from awalker_tools import cli
from awalker_tools.bagio import BODY_DESCRIPTION_TOPIC, START_DESCRIPTION_TOPIC, SequenceReader
from awalker_tools.video_to_bag import image_files, read_timestamps
from awalker_tracker.errors import InputError
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.vision.camera import Camera, save_calibration

START_YAML = "start: {frame: 0, position: [0.5, -1.0], heading: 0.3, speed: 1.2, step_length: 0.6, stance_leg: left}\n"


def calibration(tmp_path: Path) -> tuple[Path, list[Camera]]:
    cams = [
        Camera.look_at("cam0", 48, 36, 40.0, [5.0, 0.0, 1.5], [0.0, 0.0, 1.0], distortion=[0.05, 0.0, 0.0, 0.0]),
        Camera.look_at("cam1", 32, 24, 28.0, [0.0, -5.0, 2.0], [0.0, 0.0, 1.0]),
    ]
    path = tmp_path / "calibration.yaml"
    save_calibration(cams, path)
    return path, cams


def write_image_folder(folder: Path, cam: Camera, frames: int, seed: int) -> list[np.ndarray]:
    """Random RGB frames saved as PNG with names that sort wrongly as plain strings (f2 < f10)."""
    folder.mkdir()
    rng = np.random.default_rng(seed)
    images = []
    for i in range(frames):
        rgb = rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
        assert cv2.imwrite(str(folder / f"f{i}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        images.append(rgb)
    (folder / "notes.txt").write_text("not an image")
    return images


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_image_folders_round_trip_with_timestamps(tmp_path: Path, storage: str) -> None:
    cal, cams = calibration(tmp_path)
    frames = 12  # > 10 so natural ordering matters
    im0 = write_image_folder(tmp_path / "c0", cams[0], frames, 1)
    im1 = write_image_folder(tmp_path / "c1", cams[1], frames, 2)
    stamps_s = [f"1700000000.{i * 40000000:09d}" for i in range(frames)]
    (tmp_path / "stamps.txt").write_text("# seconds\n" + "\n".join(stamps_s) + "\n")
    (tmp_path / "start.yaml").write_text(START_YAML)
    (tmp_path / "body.yaml").write_text(BodyDescription.default().to_yaml_text())
    out = tmp_path / "out"
    rc = cli.main(["convert", "--calibration", str(cal), "--out", str(out), "--storage", storage,
                   "--images", f"cam0={tmp_path / 'c0'}", "--images", f"cam1={tmp_path / 'c1'}",
                   "--timestamps", str(tmp_path / "stamps.txt"), "--start-description", str(tmp_path / "start.yaml"),
                   "--body-description", str(tmp_path / "body.yaml")])
    assert rc == 0
    assert any(out.glob("*.mcap" if storage == "mcap" else "*.db3"))
    with SequenceReader(out) as reader:
        assert [c.name for c in reader.cameras] == ["cam0", "cam1"]
        np.testing.assert_allclose(reader.cameras[0].distortion, cams[0].distortion)
        got = list(reader.frames())
        assert [s for s, _ in got] == [1_700_000_000_000_000_000 + i * 40_000_000 for i in range(frames)]
        for i, (_, images) in enumerate(got):
            np.testing.assert_array_equal(images["cam0"], im0[i])
            np.testing.assert_array_equal(images["cam1"], im1[i])
        assert reader.text(START_DESCRIPTION_TOPIC) == START_YAML
        assert reader.text(BODY_DESCRIPTION_TOPIC) == BodyDescription.default().to_yaml_text()


def test_video_with_fps_from_file_compressed(tmp_path: Path) -> None:
    cal, cams = calibration(tmp_path)
    video = tmp_path / "walk.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (cams[0].width, cams[0].height))
    rng = np.random.default_rng(5)
    for _ in range(7):
        writer.write(rng.integers(0, 256, (cams[0].height, cams[0].width, 3), dtype=np.uint8))
    writer.release()
    decoded = []
    capture = cv2.VideoCapture(str(video))
    while True:
        ok, bgr = capture.read()
        if not ok:
            break
        decoded.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    capture.release()
    out = tmp_path / "out"
    assert cli.main(["convert", "--calibration", str(cal), "--out", str(out), "--compressed",
                     "--video", f"cam0={video}", "--start-time", "2.5"]) == 0
    with SequenceReader(out) as reader:
        assert reader.camera_names == ["cam0"]
        assert reader.topics["/cam0/image_raw/compressed"] == "sensor_msgs/msg/CompressedImage"
        got = list(reader.frames())
    assert [s for s, _ in got] == [2_500_000_000 + i * 40_000_000 for i in range(7)]
    for (_, images), want in zip(got, decoded):
        np.testing.assert_array_equal(images["cam0"], want)  # png keeps the decoded video frames exactly


def test_shorter_camera_truncates_and_says_so(tmp_path: Path, capsys) -> None:
    cal, cams = calibration(tmp_path)
    write_image_folder(tmp_path / "c0", cams[0], 5, 1)
    write_image_folder(tmp_path / "c1", cams[1], 3, 2)
    out = tmp_path / "out"
    assert cli.main(["convert", "--calibration", str(cal), "--out", str(out), "--fps", "30",
                     "--images", f"cam0={tmp_path / 'c0'}", "--images", f"cam1={tmp_path / 'c1'}"]) == 0
    assert "cam1 ended after 3 frames" in capsys.readouterr().err
    with SequenceReader(out) as reader:
        assert len(reader.frame_stamps) == 3


def test_image_files_natural_order_and_timestamps_parser(tmp_path: Path) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for name in ("f10.png", "f2.png", "f1.jpg", "readme.md"):
        (folder / name).write_bytes(b"")
    assert [p.name for p in image_files(folder)] == ["f1.jpg", "f2.png", "f10.png"]
    stamps = tmp_path / "t.txt"
    stamps.write_text("0.5\n\n# comment\n0.533333333 # inline\n1\n")
    assert read_timestamps(stamps) == [500_000_000, 533_333_333, 1_000_000_000]
    stamps.write_text("0.5\n0.4\n")
    with pytest.raises(InputError, match=r"t.txt:2: timestamps must increase strictly"):
        read_timestamps(stamps)
    stamps.write_text("0.5\nabc\n")
    with pytest.raises(InputError, match=r"t.txt:2: expected a timestamp in seconds"):
        read_timestamps(stamps)


def mjpg_video(tmp_path: Path, frames: int = 20) -> tuple[Path, Path]:
    """A 64x48 MJPG .avi of ``frames`` random frames at 25 fps, and its calibration."""
    path = tmp_path / "calibration64.yaml"
    save_calibration([Camera.look_at("cam0", 64, 48, 40.0, [5.0, 0.0, 1.5], [0.0, 0.0, 1.0])], path)
    video = tmp_path / "walk.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48))
    rng = np.random.default_rng(3)
    for _ in range(frames):
        writer.write(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
    writer.release()
    return video, path


def jpeg_chunks(data: bytes) -> list[tuple[int, int]]:
    """(offset, size) of each compressed frame of an AVI: its '00dc' chunks holding a JPEG (not the index's)."""
    chunks, at = [], data.find(b"00dc")
    while at >= 0:
        size = int.from_bytes(data[at + 4:at + 8], "little")
        if data[at + 8:at + 10] == b"\xff\xd8":
            chunks.append((at + 8, size))
        at = data.find(b"00dc", at + 8)
    return chunks


def convert_video(video: Path, cal: Path, out: Path, capsys) -> tuple[int, list[str]]:
    rc = cli.main(["convert", "--calibration", str(cal), "--out", str(out), "--video", f"cam0={video}"])
    return rc, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


def test_cut_off_video_warns_with_the_counts(tmp_path: Path, capsys) -> None:
    """A video cut off half way (issue 57: 23 of 48 frames were silently missing): the frames read against the
    20 its container states, in one warning line at the end; exit 0; the frames keep their stamps."""
    video, cal = mjpg_video(tmp_path)
    data = video.read_bytes()
    video.write_bytes(data[:len(data) // 2])
    rc, lines = convert_video(video, cal, tmp_path / "out", capsys)
    assert rc == 0, lines
    with SequenceReader(tmp_path / "out") as reader:
        stamps = reader.frame_stamps
    read = len(stamps)
    assert 0 < read < 20
    assert lines[-1] == (f"convert: warning: {video}: {read} of the 20 frames its container states could be "
                         f"decoded, the other {20 - read} are not in the bag (the frames written keep the stamps "
                         "of their index)"), lines
    assert list(stamps) == [i * 40_000_000 for i in range(read)]


def test_undecodable_frame_inside_a_video_keeps_the_later_stamps(tmp_path: Path, capsys) -> None:
    """Frame 5 undecodable: the 14 after it are still read (before, the video ended there), at their own stamps."""
    video, cal = mjpg_video(tmp_path)
    data = bytearray(video.read_bytes())
    offset, size = jpeg_chunks(bytes(data))[5]
    data[offset:offset + size] = bytes(size)
    video.write_bytes(bytes(data))
    rc, lines = convert_video(video, cal, tmp_path / "out", capsys)
    assert rc == 0, lines
    assert "19 of the 20 frames its container states could be decoded, the other 1 are" in lines[-1], lines
    with SequenceReader(tmp_path / "out") as reader:
        assert list(reader.frame_stamps) == [i * 40_000_000 for i in range(20) if i != 5]


def test_video_with_no_decodable_frame_is_refused(tmp_path: Path, capsys) -> None:
    video, cal = mjpg_video(tmp_path)
    data = bytearray(video.read_bytes())
    chunks = jpeg_chunks(bytes(data))
    assert len(chunks) == 20
    for offset, size in chunks:
        data[offset:offset + size] = bytes(size)
    video.write_bytes(bytes(data))
    rc, lines = convert_video(video, cal, tmp_path / "out", capsys)
    assert rc == 2
    assert lines == [f"awalker convert: error: {video}: no frame of the video can be decoded (its container "
                     "states 20)"]
    assert not (tmp_path / "out").exists()
