"""Bad inputs to convert / info / replay: one line naming the file or topic, exit 2, no traceback."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from awalker_tools import cli
from awalker_tools.bagio import SequenceReader, SequenceWriter
from awalker_tools.typestore import typestore
from awalker_tracker.errors import InputError
from awalker_tracker.vision.camera import Camera, save_calibration

CAM = Camera.look_at("cam0", 16, 12, 15.0, [3.0, 0.0, 1.5], [0.0, 0.0, 1.0])


def run_cli(args: list[str], capsys) -> tuple[int, str]:
    rc = cli.main(args)
    err = capsys.readouterr().err
    return rc, err


def assert_one_line_error(rc: int, err: str, *needles: str) -> None:
    lines = [line for line in err.splitlines() if "error:" in line]
    assert rc == 2, err
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.fixture
def setup(tmp_path: Path) -> dict[str, Path]:
    cal = tmp_path / "cal.yaml"
    save_calibration([CAM], cal)
    images = tmp_path / "imgs"
    images.mkdir()
    for i in range(3):
        cv2.imwrite(str(images / f"{i}.png"), np.full((12, 16, 3), 40 * i, np.uint8))
    return {"cal": cal, "images": images, "root": tmp_path}


def test_video_that_cannot_be_opened(setup, capsys) -> None:
    bad = setup["root"] / "broken.mp4"
    bad.write_bytes(b"\x00\x01 definitely not a video" * 50)
    out = setup["root"] / "out"
    rc, err = run_cli(["convert", "--calibration", str(setup["cal"]), "--out", str(out), "--fps", "30",
                       "--video", f"cam0={bad}"], capsys)
    assert_one_line_error(rc, err, "broken.mp4", "cannot open video")
    assert not out.exists()
    rc, err = run_cli(["convert", "--calibration", str(setup["cal"]), "--out", str(out), "--fps", "30",
                       "--video", f"cam0={setup['root'] / 'absent.mp4'}"], capsys)
    assert_one_line_error(rc, err, "absent.mp4", "video file not found")


def test_non_monotonic_timestamps(setup, capsys) -> None:
    stamps = setup["root"] / "stamps.txt"
    stamps.write_text("1.0\n1.1\n1.05\n")
    out = setup["root"] / "out"
    rc, err = run_cli(["convert", "--calibration", str(setup["cal"]), "--out", str(out),
                       "--images", f"cam0={setup['images']}", "--timestamps", str(stamps)], capsys)
    assert_one_line_error(rc, err, "stamps.txt:3", "increase strictly")
    assert not out.exists()


CALIBRATION = """cameras:
  - name: cam0
    width: 16
    height: 12
    K: [[15, 0, 7.5], [0, 15, 5.5], [0, 0, 1]]
    distortion: []
    pose: {position: [3, 0, 1.5], orientation: [0, 0, 0, 1]}
"""


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda t: t, None),  # the template itself is valid: the edits below cause the errors
        (lambda t: t.replace("    height: 12\n", ""), "missing field(s) height"),
        (lambda t: t.replace("[0, 0, 1]]", "[0, 0, 1], [1, 1, 1]]"), "expected 9 numbers"),
        (lambda t: t.replace("[3, 0, 1.5]", "[3, 0]"), "pose.position: expected 3 numbers"),
        (lambda t: t.replace("cameras:", "kameras:"), "top-level 'cameras:' list"),
    ],
)
def test_bad_calibration(setup, capsys, edit, needle) -> None:
    setup["cal"].write_text(edit(CALIBRATION))
    rc, err = run_cli(["convert", "--calibration", str(setup["cal"]), "--out", str(setup["root"] / "o"),
                       "--fps", "10", "--images", f"cam0={setup['images']}"], capsys)
    if needle is None:
        assert rc == 0, err
    else:
        assert_one_line_error(rc, err, "cal.yaml", needle)


def test_convert_source_errors(setup, capsys) -> None:
    base = ["convert", "--calibration", str(setup["cal"]), "--out", str(setup["root"] / "o")]
    rc, err = run_cli(base + ["--fps", "10", "--images", f"cam7={setup['images']}"], capsys)
    assert_one_line_error(rc, err, "cal.yaml", "no camera 'cam7'")
    rc, err = run_cli(base + ["--fps", "10", "--images", str(setup["images"])], capsys)
    assert_one_line_error(rc, err, "expected CAM=PATH")
    rc, err = run_cli(base + ["--images", f"cam0={setup['images']}"], capsys)
    assert_one_line_error(rc, err, "--fps")
    empty = setup["root"] / "empty"
    empty.mkdir()
    rc, err = run_cli(base + ["--fps", "10", "--images", f"cam0={empty}"], capsys)
    assert_one_line_error(rc, err, "empty", "no images")
    cv2.imwrite(str(setup["images"] / "3.png"), np.zeros((13, 16, 3), np.uint8))
    rc, err = run_cli(base + ["--fps", "10", "--images", f"cam0={setup['images']}"], capsys)
    assert_one_line_error(rc, err, "3.png", "16x13", "16x12")
    assert not (setup["root"] / "o").exists()  # the partial bag is removed
    (setup["root"] / "start.yaml").write_text("start: {heading: 0}\n")
    (setup["images"] / "3.png").unlink()
    rc, err = run_cli(base + ["--fps", "10", "--images", f"cam0={setup['images']}",
                              "--start-description", str(setup["root"] / "start.yaml")], capsys)
    assert_one_line_error(rc, err, "start.yaml", "missing position")
    assert cli.main(base + ["--fps", "10", "--images", f"cam0={setup['images']}"]) == 0
    rc, err = run_cli(base + ["--fps", "10", "--images", f"cam0={setup['images']}"], capsys)
    assert_one_line_error(rc, err, "exists already")


def test_missing_and_corrupt_bags(setup, capsys) -> None:
    root = setup["root"]
    for command in (["info"], ["replay", "--wait-for-subscribers", "0"]):
        rc, err = run_cli([*command, str(root / "nobag")], capsys)
        assert_one_line_error(rc, err, "nobag", "bag not found")
    corrupt = root / "corrupt"
    corrupt.mkdir()
    (corrupt / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
    rc, err = run_cli(["info", str(corrupt)], capsys)
    assert_one_line_error(rc, err, "corrupt", "rosbag2")
    garbage = root / "garbage.db3"
    garbage.write_bytes(b"SQLite format 3\x00" + b"\xff" * 200)
    rc, err = run_cli(["info", str(garbage)], capsys)
    assert_one_line_error(rc, err, "garbage.db3")


def test_unknown_image_encoding_names_topic(setup) -> None:
    bag = setup["root"] / "float"
    types = typestore().types
    with SequenceWriter(bag, [CAM]) as writer:
        writer.write_frame(1, {"cam0": np.zeros((12, 16, 3), np.uint8)})
        header = types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](0, 2), "cam0_optical_frame")
        msg = types["sensor_msgs/msg/Image"](header, 12, 16, "32FC1", 0, 64, np.zeros(12 * 64, np.uint8))
        writer.write_message("/cam0/image_raw", "sensor_msgs/msg/Image", 2, msg)
    with SequenceReader(bag) as reader:
        with pytest.raises(InputError, match=r"/cam0/image_raw: unsupported image encoding '32FC1'; expected one of"):
            list(reader.frames())


def test_user_error_from_the_real_console_script_has_no_traceback(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "awalker_tools.cli", "info", str(tmp_path / "missing")],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [f"awalker info: error: {tmp_path / 'missing'}: bag not found"]
