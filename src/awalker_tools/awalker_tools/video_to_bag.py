"""Convert videos or image folders plus a calibration YAML into a sequence bag.

Several cameras are synchronised by frame index: frame i of every source gets the same stamp. A video frame
the decoder cannot read is left out (with the other cameras' frame of that index) and counted in a warning
against the frame count the container states; the frames written keep the stamps of their index.
Stamps come from a timestamps file (one per frame, seconds, increasing) or from the frame rate
(the video's, or ``fps``) starting at ``start_time``.
"""
from __future__ import annotations

import re
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import cv2
import numpy as np

from awalker_tracker.errors import InputError
from awalker_tracker.inference.filter_model import StartDescription
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.vision.camera import Camera, load_calibration

from awalker_tools.bagio import BODY_DESCRIPTION_TOPIC, START_DESCRIPTION_TOPIC, SequenceWriter

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")
PROGRESS_PERIOD_S = 2.0
#: A ROS stamp's seconds are an int32 (builtin_interfaces/Time): stamps must lie before 2^31 s, 2038-01-19.
MAX_STAMP_S = 2**31
#: Frame rates ``--fps`` takes (frames/s): a frame every 10 s up to a high-speed camera's.
FPS_RANGE = (0.1, 10000.0)
#: Undecodable video frames in a row after which the rest of a video counts as cut off (a header stating 2^31
#: frames would otherwise be read to its end; a failed read takes some microseconds).
UNREADABLE_RUN_STOP = 10000


@dataclass(frozen=True)
class Source:
    """Frames of one camera: a video file (kind "video") or a folder of images (kind "images")."""

    camera: str
    kind: str
    path: Path


def parse_source(text: str, kind: str) -> Source:
    """'CAM=PATH' -> Source; InputError if malformed."""
    cam, sep, path = text.partition("=")
    if not sep or not cam or not path:
        option = "--video" if kind == "video" else "--images"
        raise InputError(f"{option} {text!r}: expected CAM=PATH (e.g. cam0=walk.mp4)")
    return Source(cam, kind, Path(path))


def _natural_key(path: Path) -> list:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name)]


def image_files(folder: Path) -> list[Path]:
    """Image files in ``folder`` in natural order (frame2 before frame10)."""
    if not folder.is_dir():
        raise InputError(f"{folder}: image folder not found")
    files = sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
    if not files:
        raise InputError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in folder")
    return files


def _check_size(rgb: np.ndarray, camera: Camera, where: str) -> np.ndarray:
    if rgb.shape[:2] != (camera.height, camera.width):
        raise InputError(f"{where}: image is {rgb.shape[1]}x{rgb.shape[0]}, calibration of camera {camera.name} "
                         f"says {camera.width}x{camera.height}")
    return rgb


@dataclass
class FrameTally:
    """What a source gave: frames decoded, and for a video the frame count its container states (None when it
    states none)."""

    read: int = 0
    stated: int | None = None
    ended: bool = False         # read to its end (not stopped early by a shorter camera)


def read_frames(source: Source, camera: Camera, tally: FrameTally | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """(frame index, HxWx3 uint8 RGB frame) of a source, checked against the camera's size. A video frame the
    decoder cannot read is left out and its index skipped (up to the count the container states; without one
    the video ends there); counts go to ``tally``. A video none of whose frames decode is an ``InputError``."""
    tally = tally if tally is not None else FrameTally()
    if source.kind == "images":
        for index, path in enumerate(image_files(source.path)):
            bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if bgr is None:
                raise InputError(f"{path}: cannot read image")
            yield index, _check_size(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), camera, str(path))
            tally.read += 1
        return
    capture = open_video(source.path)
    try:
        stated = int(capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        tally.stated = stated if stated > 0 else None
        index = failed = 0
        while True:
            ok, bgr = capture.read()
            if ok:
                tally.read += 1
                failed = 0
                yield index, _check_size(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), camera, f"{source.path} frame {index}")
            elif index >= stated - 1 or failed >= UNREADABLE_RUN_STOP:   # the container's last frame (or it states
                break                                                  # none), or cut off: the video ends here
            else:
                failed += 1
            index += 1
        tally.ended = True
        if tally.read == 0:
            raise InputError(f"{source.path}: no frame of the video can be decoded"
                             + (f" (its container states {stated})" if stated > 0 else ""))
    finally:
        capture.release()


def open_video(path: Path) -> cv2.VideoCapture:
    if not path.is_file():
        raise InputError(f"{path}: video file not found")
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        capture.release()
        raise InputError(f"{path}: cannot open video (not a video file or codec not supported by OpenCV)")
    return capture


def video_fps(path: Path) -> float:
    capture = open_video(path)
    try:
        return float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
    finally:
        capture.release()


def check_timing(fps: float | None, start_time: float) -> None:
    """``--fps`` within ``FPS_RANGE`` (when given) and ``--start-time`` a stamp ROS can hold: one-line
    ``InputError`` naming the option and the range (NaN and infinities included)."""
    if fps is not None and not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise InputError(f"--fps must lie in {FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} frames/s, got {fps:g}")
    if not 0 <= start_time < MAX_STAMP_S:
        raise InputError(f"--start-time must lie in 0-{MAX_STAMP_S} s (a ROS stamp: seconds since 1970, before "
                         f"2038-01-19), got {start_time:g}")


def check_stamp(stamp_ns: int, where: str) -> int:
    """``stamp_ns`` if a ROS stamp can hold it (before ``MAX_STAMP_S``), else a one-line ``InputError``."""
    if not 0 <= stamp_ns < MAX_STAMP_S * 1_000_000_000:
        raise InputError(f"{where}: stamp {stamp_ns / 1e9:.9g} s: expected seconds since 1970 below {MAX_STAMP_S} "
                         "(2^31, 2038-01-19), the most a ROS stamp holds")
    return stamp_ns


def read_timestamps(path: Path) -> list[int]:
    """Timestamps file: one stamp per frame in seconds (decimal), '#' comments; -> ns, strictly increasing."""
    try:
        lines = Path(path).read_text().splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read timestamps file ({exc.strerror or exc})") from None
    stamps: list[int] = []
    for number, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].strip().rstrip(",")
        if not text:
            continue
        try:
            value = Decimal(text.split(",")[0].split()[0])
        except InvalidOperation:
            raise InputError(f"{path}:{number}: expected a timestamp in seconds, got {line.strip()!r}") from None
        if not value.is_finite() or value < 0:
            raise InputError(f"{path}:{number}: timestamp must be a finite number >= 0 s, got {text!r}")
        ns = check_stamp(int(value * 1_000_000_000), f"{path}:{number}")
        if stamps and ns <= stamps[-1]:
            raise InputError(f"{path}:{number}: timestamps must increase strictly, {text} s is not after the "
                             f"previous one ({stamps[-1] / 1e9:.9f} s)")
        stamps.append(ns)
    if not stamps:
        raise InputError(f"{path}: no timestamps found (expected one number of seconds per line)")
    return stamps


def read_description(path: Path, kind: str) -> str:
    """A start/body description YAML file's text, validated by the parser the tracker uses."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise InputError(f"{path}: cannot read {kind} description ({exc.strerror or exc})") from None
    parse = StartDescription.from_yaml_text if kind == "start" else BodyDescription.from_yaml_text
    parse(text, f"{path} ({kind} description)")
    return text


def convert(
    calibration: Path,
    out: Path,
    sources: list[Source],
    storage: str = "mcap",
    compressed: bool = False,
    image_format: str = "png",
    timestamps: Path | None = None,
    fps: float | None = None,
    start_time: float = 0.0,
    start_description: Path | None = None,
    body_description: Path | None = None,
) -> int:
    """Write the bag; returns the number of frames. Progress lines go to stderr."""
    if not sources:
        raise InputError("convert: give at least one --video CAM=PATH or --images CAM=DIR")
    check_timing(fps, start_time)
    stamps = read_timestamps(timestamps) if timestamps is not None else None
    cameras = {c.name: c for c in load_calibration(calibration)}
    seen: set[str] = set()
    for source in sources:
        if source.camera not in cameras:
            raise InputError(f"{calibration}: no camera {source.camera!r} (source {source.path}); "
                             f"calibration has {sorted(cameras)}")
        if source.camera in seen:
            raise InputError(f"convert: camera {source.camera} given twice")
        seen.add(source.camera)
    if stamps is None and fps is None:
        rates = {s.path: video_fps(s.path) for s in sources if s.kind == "video"}
        if not rates or any(r <= 0 for r in rates.values()):
            raise InputError("convert: cannot tell the frame rate; give --fps F or --timestamps FILE"
                             + (f" (videos report {rates})" if rates else " (image folders have no frame rate)"))
        if len({round(r, 3) for r in rates.values()}) > 1:
            raise InputError(f"convert: videos have different frame rates {rates}; give --fps or --timestamps")
        fps = next(iter(rates.values()))
    texts = {}
    if start_description is not None:
        texts[START_DESCRIPTION_TOPIC] = read_description(start_description, "start")
    if body_description is not None:
        texts[BODY_DESCRIPTION_TOPIC] = read_description(body_description, "body")
    # Open every source before creating the bag, so a bad one fails without leaving output behind.
    counts = []
    for source in sources:
        if source.kind == "video":
            capture = open_video(source.path)
            counts.append(int(capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0))
            capture.release()
        else:
            counts.append(len(image_files(source.path)))
    start_ns = int(Decimal(str(start_time)) * 1_000_000_000)
    if stamps is None and max(counts) > 1:     # the last frame's stamp too, before any work
        check_stamp(start_ns + round((max(counts) - 1) * 1e9 / fps), f"--fps {fps:g} with --start-time "  # type: ignore[operator]
                    f"{start_time:.10g}: frame {max(counts) - 1}")
    used = [cameras[s.camera] for s in sources]
    tallies = {s.camera: FrameTally() for s in sources}
    streams = {s.camera: read_frames(s, cameras[s.camera], tallies[s.camera]) for s in sources}
    frames = end = 0
    last_print = time.monotonic()
    with SequenceWriter(out, used, storage=storage, compressed=compressed, image_format=image_format) as writer:
        heads = {cam: next(stream, None) for cam, stream in streams.items()}
        while True:
            ended = sorted(cam for cam, head in heads.items() if head is None)
            if ended:
                if len(ended) < len(heads):
                    print(f"convert: {', '.join(ended)} ended after {frames} frames; stopping there "
                          "(cameras are synchronised by frame index)", file=sys.stderr)
                break
            index = max(head[0] for head in heads.values())  # type: ignore[index]
            if any(head[0] != index for head in heads.values()):  # type: ignore[index]
                # a camera's frame could not be decoded: the frame index is left out for every camera
                heads = {cam: head if head[0] == index else next(streams[cam], None)  # type: ignore[index]
                         for cam, head in heads.items()}
                continue
            if stamps is not None:
                if index >= len(stamps):
                    raise InputError(f"{timestamps}: {len(stamps)} timestamps but the sources have more frames")
                stamp = stamps[index]
            else:
                stamp = check_stamp(start_ns + round(index * 1e9 / fps), f"frame {index}")  # type: ignore[operator]
            if frames == 0:
                for topic, text in texts.items():
                    writer.write_text(topic, stamp, text)
            writer.write_frame(stamp, {cam: head[1] for cam, head in heads.items()})  # type: ignore[index]
            frames += 1
            end = index + 1
            heads = {cam: next(stream, None) for cam, stream in streams.items()}
            if time.monotonic() - last_print >= PROGRESS_PERIOD_S:
                last_print = time.monotonic()
                print(f"convert: {frames} frames written", file=sys.stderr)
        if stamps is not None and end < len(stamps):
            print(f"convert: note: {len(stamps)} timestamps for {end} frames; the rest are unused", file=sys.stderr)
    print(f"convert: wrote {frames} frames from {len(sources)} camera(s) to {out}", file=sys.stderr)
    short = [f"{source.path}: {tally.read} of the {tally.stated} frames its container states could be decoded, "
             f"the other {tally.stated - tally.read} are not in the bag" for source in sources
             if (tally := tallies[source.camera]).ended and (tally.stated or 0) > tally.read]
    if short:
        print(f"convert: warning: {'; '.join(short)} (the frames written keep the stamps of their index)",
              file=sys.stderr)
    return frames
