"""Image messages -> RGB arrays: the one decoder of sensor_msgs/Image and sensor_msgs/CompressedImage.

Every reader of images uses it: the features node, the bag reader (``awalker_tools.bagio``) and through it
the overlays, evaluation and tools. It reads the messages' fields only, so it takes rclpy and rosbags
messages alike and imports neither.

Raw images (``decode_raw``): ``rgb8``, ``bgr8``, ``mono8``, ``rgba8``, ``bgra8`` (alpha dropped) and
16-bit grey ``mono16`` / ``16UC1`` (byte order from ``is_bigendian``). Sixteen bits become eight linearly,
0..65535 onto 0..255 (value / 257, rounded), as cv_bridge converts mono16 to mono8: a fixed mapping, not a
per-frame stretch, so that the same light gives the same grey in every frame (the background model
compares frames). Rows may be padded: ``step`` bytes per row, the first ``width`` pixels used. An rgb8
image without padding is returned as a view of the message's bytes (no copy).

Compressed images (``decode_compressed``): JPEG (data starting FF D8 FF) and PNG (89 50 4E 47 0D 0A 1A 0A)
are recognised by their bytes, whatever the message's ``format`` string says (drivers write "jpeg",
"rgb8; jpeg compressed bgr8", "" or worse); anything else, and data that does not decode, is an
``InputError`` naming the topic and what was expected; a raw encoding not listed above is the subclass
``UnsupportedEncoding`` (no image of that topic can be read, where corrupt data spoils one image).
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from awalker_tracker.errors import InputError

#: Raw encodings and their bytes per pixel.
RAW_ENCODINGS: dict[str, int] = {"rgb8": 3, "bgr8": 3, "mono8": 1, "rgba8": 4, "bgra8": 4, "mono16": 2, "16UC1": 2}
JPEG_MAGIC = b"\xff\xd8\xff"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_ENCODING_NAMES = {name.lower(): name for name in RAW_ENCODINGS}     # encodings are matched regardless of case


class UnsupportedEncoding(InputError):
    """A raw image encoding ``decode_raw`` cannot read (a property of the stream, not of one damaged image)."""


def _bytes(data: Any) -> np.ndarray:
    """A message's uint8[] field (bytes, array.array('B'), numpy array or list) as a flat uint8 array,
    without copying when it supports the buffer protocol."""
    try:
        return np.frombuffer(data, np.uint8)
    except (TypeError, ValueError):
        return np.asarray(data, np.uint8).reshape(-1)


def decode_raw(encoding: str, width: int, height: int, step: int, data: Any, where: str,
               big_endian: bool = False) -> np.ndarray:
    """(height, width, 3) uint8 RGB from the fields of a sensor_msgs/Image (see the module docstring).

    ``where`` names the topic in errors: an unknown encoding, a size of zero, a step shorter than a row or
    data shorter than ``step * height`` bytes."""
    name = _ENCODING_NAMES.get(str(encoding).lower())
    if name is None:
        raise UnsupportedEncoding(f"{where}: unsupported image encoding {encoding!r}; expected one of "
                         f"{', '.join(RAW_ENCODINGS)} (or a CompressedImage)")
    channels = RAW_ENCODINGS[name]
    width, height, step = int(width), int(height), int(step)
    pixels = _bytes(data)
    if width <= 0 or height <= 0 or step < width * channels or pixels.size < step * height:
        raise InputError(f"{where}: {width}x{height} {name} image with step {step} has {pixels.size} bytes; "
                         f"expected width and height > 0, step >= {max(width, 0) * channels} and at least "
                         f"step x height bytes")
    rows = pixels[: step * height].reshape(height, step)[:, : width * channels]
    if channels == 2:
        wide = rows.copy().view(">u2" if big_endian else "<u2").astype(np.uint32)
        grey = ((wide * 255 + 32767) // 65535).astype(np.uint8)
        return np.repeat(grey[..., None], 3, axis=2)
    rows = rows.reshape(height, width, channels)
    if channels == 1:
        return np.repeat(rows, 3, axis=2)
    if name.startswith("bgr"):
        return np.ascontiguousarray(rows[..., 2::-1])
    return np.ascontiguousarray(rows[..., :3])


def decode_compressed(data: Any, where: str, fmt: str = "") -> np.ndarray:
    """(H, W, 3) uint8 RGB from the data of a sensor_msgs/CompressedImage, JPEG or PNG by its bytes
    (``fmt``, the message's format string, is only quoted in errors)."""
    raw = _bytes(data)
    head = raw[:8].tobytes()
    if head.startswith(JPEG_MAGIC):
        kind = "JPEG"
    elif head.startswith(PNG_MAGIC):
        kind = "PNG"
    else:
        raise InputError(f"{where}: compressed image data ({raw.size} bytes, format {fmt!r}) is neither JPEG "
                         f"nor PNG: it starts {head.hex(' ') or 'with nothing'}; expected ff d8 ff (JPEG) or "
                         f"89 50 4e 47 0d 0a 1a 0a (PNG)")
    rgb = cv2.imdecode(raw, cv2.IMREAD_COLOR_RGB)
    if rgb is None:
        raise InputError(f"{where}: corrupt or truncated {kind} data ({raw.size} bytes, format {fmt!r})")
    return rgb


def decode_image(msg: Any, where: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB from a sensor_msgs/Image or CompressedImage (rclpy or rosbags; a message with a
    ``format`` string field is taken for a CompressedImage)."""
    if isinstance(getattr(msg, "format", None), str) and hasattr(msg, "data"):
        return decode_compressed(msg.data, where, msg.format)
    if not (isinstance(getattr(msg, "encoding", None), str) and hasattr(msg, "data")):
        raise InputError(f"{where}: expected a sensor_msgs/Image or CompressedImage, got {type(msg).__name__}")
    return decode_raw(str(msg.encoding), msg.width, msg.height, msg.step, msg.data, where,
                      bool(getattr(msg, "is_bigendian", False)))


def decode_mono8(msg: Any, where: str) -> np.ndarray:
    """(H, W) uint8 from a mono8 sensor_msgs/Image (occlusion masks, label images); any other encoding is an
    ``InputError``."""
    if str(getattr(msg, "encoding", "")).lower() != "mono8":
        raise InputError(f"{where}: encoding {getattr(msg, 'encoding', None)!r}; expected mono8")
    return decode_image(msg, where)[..., 0]
