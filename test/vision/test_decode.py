"""The one image decoder (vision/decode.py): every raw encoding, padded rows, JPEG and PNG recognised by
their bytes whatever the format string says, and a clear error for everything else; rclpy and rosbags
messages alike."""
from __future__ import annotations

import array

import cv2
import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.vision.decode import decode_compressed, decode_image, decode_mono8, decode_raw

RGB = np.random.default_rng(3).integers(0, 256, (5, 7, 3), dtype=np.uint8)
#: a picture JPEG keeps well: 8x8 blocks of one colour each, red, green and blue unequal
BLOCKS = np.kron(np.random.default_rng(4).integers(0, 256, (3, 4, 3)), np.ones((8, 8, 1))).astype(np.uint8)


def padded(pixels: np.ndarray, pad: int) -> tuple[int, bytes]:
    """(step, data) of an (H, W, C) uint8 image with ``pad`` junk bytes after every row."""
    h = pixels.shape[0]
    rows = pixels.reshape(h, -1)
    junk = np.full((h, pad), 0xAB, np.uint8)
    return rows.shape[1] + pad, np.ascontiguousarray(np.hstack([rows, junk])).tobytes()


@pytest.mark.parametrize("pad", [0, 3])
def test_every_raw_encoding_gives_the_rgb_image(pad: int) -> None:
    h, w = RGB.shape[:2]
    alpha = np.full((h, w, 1), 77, np.uint8)
    sources = {
        "rgb8": RGB, "bgr8": RGB[..., ::-1], "rgba8": np.concatenate([RGB, alpha], 2),
        "bgra8": np.concatenate([RGB[..., ::-1], alpha], 2),
    }
    for encoding, pixels in sources.items():
        step, data = padded(np.ascontiguousarray(pixels), pad)
        out = decode_raw(encoding, w, h, step, data, "/cam/image_raw")
        assert out.dtype == np.uint8 and out.shape == (h, w, 3) and out.flags.c_contiguous, encoding
        np.testing.assert_array_equal(out, RGB, err_msg=encoding)
    grey = RGB[..., 0]
    step, data = padded(grey[..., None], pad)
    np.testing.assert_array_equal(decode_raw("mono8", w, h, step, data, "t"), np.repeat(grey[..., None], 3, 2))
    # upper-case names too (drivers differ)
    step, data = padded(np.ascontiguousarray(RGB), pad)
    np.testing.assert_array_equal(decode_raw("RGB8", w, h, step, data, "t"), RGB)


def test_an_unpadded_rgb8_image_is_not_copied() -> None:
    data = bytearray(RGB.tobytes())
    out = decode_raw("rgb8", RGB.shape[1], RGB.shape[0], 3 * RGB.shape[1], data, "t")
    data[0] = (int(RGB[0, 0, 0]) + 1) % 256
    assert out[0, 0, 0] == data[0]


@pytest.mark.parametrize("encoding", ["mono16", "16UC1"])
@pytest.mark.parametrize("big_endian", [False, True])
def test_sixteen_bit_grey_maps_0_65535_onto_0_255(encoding: str, big_endian: bool) -> None:
    values = np.array([[0, 128, 129, 257, 1000], [32767, 32768, 65278, 65534, 65535]], np.uint16)
    raw = values.astype(">u2" if big_endian else "<u2")
    step, data = padded(raw.view(np.uint8).reshape(2, 5, 2), 2)
    out = decode_raw(encoding, 5, 2, step, data, "/depth", big_endian=big_endian)
    expected = np.round(values / 257.0).astype(np.uint8)            # linear, as cv_bridge's mono16 -> mono8
    np.testing.assert_array_equal(out, np.repeat(expected[..., None], 3, 2))
    assert expected.tolist() == [[0, 0, 1, 1, 4], [127, 128, 254, 255, 255]]


@pytest.mark.parametrize("ext", [".jpg", ".png"])
@pytest.mark.parametrize("fmt", ["jpeg", "png", "tiff", "", "rgb8; jpeg compressed bgr8", "rgb8; png compressed bgr8",
                                 "bmp"])
def test_jpeg_and_png_are_told_by_their_bytes_whatever_the_format_says(ext: str, fmt: str) -> None:
    data = cv2.imencode(ext, BLOCKS[..., ::-1])[1].tobytes()
    out = decode_compressed(data, "/cam/image_raw/compressed", fmt)
    assert out.shape == BLOCKS.shape and out.dtype == np.uint8
    if ext == ".png":
        np.testing.assert_array_equal(out, BLOCKS)                   # lossless
    else:                                                            # lossy, but the same picture, in RGB order
        error = np.abs(out.astype(int) - BLOCKS).mean()
        assert error < 8 and error < np.abs(out.astype(int) - BLOCKS[..., ::-1]).mean() / 4


def test_grey_and_alpha_pngs_give_three_channels() -> None:
    grey = RGB[..., 1]
    out = decode_compressed(cv2.imencode(".png", grey)[1].tobytes(), "t", "mono8; png compressed")
    np.testing.assert_array_equal(out, np.repeat(grey[..., None], 3, 2))
    bgra = np.concatenate([RGB[..., ::-1], np.full(RGB.shape[:2] + (1,), 9, np.uint8)], 2)
    np.testing.assert_array_equal(decode_compressed(cv2.imencode(".png", bgra)[1].tobytes(), "t"), RGB)


def test_other_compressed_data_is_a_clear_error() -> None:
    with pytest.raises(InputError, match=r"^/c: compressed image data \(4 bytes, format 'tiff'\) is neither JPEG nor "
                                         r"PNG: it starts 49 49 2a 00; expected ff d8 ff \(JPEG\)"):
        decode_compressed(b"II*\x00", "/c", "tiff")                  # a real TIFF header
    with pytest.raises(InputError, match=r"^/c: .*starts with nothing"):
        decode_compressed(b"", "/c", "jpeg")
    for ext, kind in ((".jpg", "JPEG"), (".png", "PNG")):
        whole = cv2.imencode(ext, RGB[..., ::-1])[1].tobytes()
        for cut in (len(whole) // 2, len(whole) - 2):
            with pytest.raises(InputError, match=rf"^/c: corrupt or truncated {kind} data \({cut} bytes"):
                decode_compressed(whole[:cut], "/c", "jpeg")
    broken = bytearray(cv2.imencode(".png", RGB[..., ::-1])[1].tobytes())
    broken[40:60] = bytes(20)
    with pytest.raises(InputError, match="corrupt or truncated PNG"):
        decode_compressed(bytes(broken), "/c")


def test_raw_errors_name_the_topic_and_what_was_expected() -> None:
    data = RGB.tobytes()
    with pytest.raises(InputError, match=r"^/cam0/image_raw: unsupported image encoding 'yuv422'; expected one of "
                                         r"rgb8, bgr8, mono8, rgba8, bgra8, mono16, 16UC1"):
        decode_raw("yuv422", 7, 5, 21, data, "/cam0/image_raw")
    with pytest.raises(InputError, match=r"^/s: 7x6 rgb8 image with step 21 has 105 bytes; expected"):
        decode_raw("rgb8", 7, 6, 21, data, "/s")                      # data shorter than step x height
    with pytest.raises(InputError, match=r"step >= 21"):
        decode_raw("rgb8", 7, 5, 20, data, "/s")                      # step shorter than a row
    with pytest.raises(InputError, match=r"width and height > 0"):
        decode_raw("rgb8", 0, 5, 21, data, "/s")
    with pytest.raises(InputError, match=r"^/x: expected a sensor_msgs/Image or CompressedImage, got str"):
        decode_image("pixels", "/x")


def test_rclpy_and_rosbags_messages_decode_alike() -> None:
    from sensor_msgs.msg import CompressedImage, Image

    from awalker_tools.typestore import typestore

    h, w = RGB.shape[:2]
    step, data = padded(np.concatenate([RGB, np.zeros((h, w, 1), np.uint8)], 2), 4)
    live = Image(height=h, width=w, encoding="rgba8", step=step)
    live.data = array.array("B", data)
    types = typestore().types
    header = types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](0, 0), "f")
    stored = types["sensor_msgs/msg/Image"](header, h, w, "rgba8", 0, step, np.frombuffer(data, np.uint8))
    for msg in (live, stored):
        np.testing.assert_array_equal(decode_image(msg, "/cam/image_raw"), RGB)
    jpeg = cv2.imencode(".jpg", RGB[..., ::-1])[1].tobytes()
    live_c = CompressedImage(format="")
    live_c.data = jpeg
    stored_c = types["sensor_msgs/msg/CompressedImage"](header, "tiff", np.frombuffer(jpeg, np.uint8))
    np.testing.assert_array_equal(decode_image(live_c, "t"), decode_image(stored_c, "t"))
    mask = Image(height=1, width=3, encoding="mono8", step=3)
    mask.data = bytes([0, 255, 7])
    assert decode_mono8(mask, "/m").tolist() == [[0, 255, 7]]
    mask.encoding = "rgb8"
    with pytest.raises(InputError, match=r"^/m: encoding 'rgb8'; expected mono8"):
        decode_mono8(mask, "/m")
