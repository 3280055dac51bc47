"""Sequence bags: write and read the rosbag2 files awalker works on (mcap or sqlite3, via rosbags).

Topics (per camera ``<cam>``; common.md "Bag topics"):

- ``/<cam>/image_raw`` sensor_msgs/Image or ``/<cam>/image_raw/compressed`` sensor_msgs/CompressedImage
  (the encodings and formats ``awalker_tracker.vision.decode`` reads; written: rgb8, or png/jpeg), one per
  frame; header.stamp = frame stamp;
- ``/<cam>/camera_info`` sensor_msgs/CameraInfo, one per frame;
- ``/tf_static`` tf2_msgs/TFMessage, once: ``world`` -> ``<cam>_optical_frame`` for every camera;
- optional ``/<cam>/occlusion_mask`` (mono8, 255 = occluded), ``/awalker/ground_truth``
  (awalker_msgs/BodyPose), ``/awalker/start_description`` and ``/awalker/body_description``
  (std_msgs/String with YAML text, once).

Latched topics (``/tf_static``, the descriptions) carry a TRANSIENT_LOCAL QoS profile in the
bag metadata so replay can publish them latched. Message log time = header stamp.
Every user error (missing, corrupt or truncated bag, missing topics, unknown encodings) is an
``InputError`` naming the bag or topic and what was expected.
"""
from __future__ import annotations

import shutil
import struct
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import numpy as np
from rosbags.interfaces import Connection, Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.rosbag2.errors import ReaderError, WriterError
from scipy.spatial.transform import Rotation

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.vision.camera import Camera, camera_from_info
from awalker_tracker.vision.decode import decode_image, decode_mono8

from awalker_tools.typestore import typestore

WORLD_FRAME = "world"
TF_STATIC_TOPIC = "/tf_static"
GROUND_TRUTH_TOPIC = "/awalker/ground_truth"
START_DESCRIPTION_TOPIC = "/awalker/start_description"
BODY_DESCRIPTION_TOPIC = "/awalker/body_description"
LATCHED_TOPICS = (TF_STATIC_TOPIC, START_DESCRIPTION_TOPIC, BODY_DESCRIPTION_TOPIC)

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STRING = "std_msgs/msg/String"
BODY_POSE = "awalker_msgs/msg/BodyPose"
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
IMAGE_FORMATS = ("png", "jpeg")

# Errors the rosbags storage back-ends raise on damaged files (besides ReaderError).
_BAG_DATA_ERRORS = (ReaderError, struct.error, EOFError, OSError, ValueError, IndexError, KeyError, AssertionError)


def image_topic(cam: str, compressed: bool) -> str:
    return f"/{cam}/image_raw/compressed" if compressed else f"/{cam}/image_raw"


def camera_info_topic(cam: str) -> str:
    return f"/{cam}/camera_info"


def occlusion_mask_topic(cam: str) -> str:
    return f"/{cam}/occlusion_mask"


def _qos(latched: bool) -> Qos:
    """Offered QoS recorded in the bag: reliable; latched topics transient-local, depth 1."""
    zero = QosTime(0, 0)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1 if latched else 10,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        deadline=zero,
        lifespan=zero,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero,
        avoid_ros_namespace_conventions=False,
    )


def is_latched(connection: Connection) -> bool:
    """True if the bag offered this topic transient-local (or it is a known latched topic)."""
    profiles = getattr(connection.ext, "offered_qos_profiles", None) or []
    return connection.topic in LATCHED_TOPICS or any(
        p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles
    )


def _stamp(stamp_ns: int) -> Any:
    Time = typestore().types["builtin_interfaces/msg/Time"]
    return Time(sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))


def _header(stamp_ns: int, frame_id: str) -> Any:
    return typestore().types["std_msgs/msg/Header"](stamp=_stamp(stamp_ns), frame_id=frame_id)


def stamp_ns_of(header: Any) -> int:
    """Header stamp as integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _rgb_image(image: Any, where: str, width: int | None = None, height: int | None = None) -> np.ndarray:
    arr = np.asarray(image)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(f"{where}: expected an HxWx3 uint8 RGB image, got {arr.dtype} {arr.shape}")
    if width is not None and arr.shape[:2] != (height, width):
        raise InputError(f"{where}: expected {width}x{height} pixels (calibration), got {arr.shape[1]}x{arr.shape[0]}")
    return np.ascontiguousarray(arr)


def torso_quaternion(markers: np.ndarray) -> np.ndarray:
    """Torso orientation (qx, qy, qz, qw) from 13 markers (order MARKER_NAMES), world frame.

    Body axes: z up the spine (pelvis -> thorax), y to the left (right_hip -> left_hip,
    orthogonalised), x = y x z forward.
    """
    up = markers[1] - markers[0]
    left = markers[3] - markers[4]
    up_norm = np.linalg.norm(up)
    if up_norm < 1e-9:
        return np.array([0.0, 0.0, 0.0, 1.0])
    up = up / up_norm
    left = left - up * (left @ up)
    left_norm = np.linalg.norm(left)
    if left_norm < 1e-9:
        return np.array([0.0, 0.0, 0.0, 1.0])
    left /= left_norm
    forward = np.cross(left, up)
    return Rotation.from_matrix(np.stack([forward, left, up], axis=1)).as_quat()


class SequenceWriter:
    """Write a sequence bag (context manager). Removes the partial bag if the block raises.

    ``cameras``: calibrated cameras; ``storage``: "mcap" (Jazzy default) or "sqlite3";
    ``compressed``: images as CompressedImage in ``image_format`` ("png" lossless, "jpeg").
    """

    def __init__(
        self,
        path: str | Path,
        cameras: list[Camera],
        storage: str = "mcap",
        compressed: bool = False,
        image_format: str = "png",
    ) -> None:
        self.path = Path(path)
        if storage not in STORAGES:
            raise InputError(f"{self.path}: storage must be one of {sorted(STORAGES)}, got {storage!r}")
        if image_format not in IMAGE_FORMATS:
            raise InputError(f"{self.path}: image format must be one of {IMAGE_FORMATS}, got {image_format!r}")
        if not cameras:
            raise InputError(f"{self.path}: at least one camera is needed")
        if self.path.exists():
            raise InputError(f"{self.path}: output bag exists already; choose a new path or remove it")
        self.cameras = {c.name: c for c in cameras}
        self.storage = storage
        self.compressed = compressed
        self.image_format = image_format
        self._writer: Writer | None = None
        self._connections: dict[str, Connection] = {}
        self._last_frame_ns: int | None = None
        self._static_written = False
        self.frames_written = 0

    # -- context management -------------------------------------------------------------------
    def __enter__(self) -> "SequenceWriter":
        self._writer = Writer(self.path, version=9, storage_plugin=STORAGES[self.storage])
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            self._writer = None
            raise InputError(f"{self.path}: cannot create bag ({exc})") from None
        for name in self.cameras:
            img_type = COMPRESSED_IMAGE if self.compressed else IMAGE
            self._add(image_topic(name, self.compressed), img_type)
            self._add(camera_info_topic(name), CAMERA_INFO)
        self._add(TF_STATIC_TOPIC, TF_MESSAGE, latched=True)
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        writer, self._writer = self._writer, None
        if writer is None:
            return
        if exc_type is None:
            writer.close()
            return
        try:
            writer.abort()
        finally:
            shutil.rmtree(self.path, ignore_errors=True)

    def _add(self, topic: str, msgtype: str, latched: bool = False) -> Connection:
        if topic in self._connections:
            conn = self._connections[topic]
            if conn.msgtype != msgtype:
                raise InputError(f"{self.path}: topic {topic} already holds {conn.msgtype}, not {msgtype}")
            return conn
        assert self._writer is not None, "SequenceWriter used outside its with-block"
        conn = self._writer.add_connection(
            topic, msgtype, typestore=typestore(), offered_qos_profiles=[_qos(latched or topic in LATCHED_TOPICS)]
        )
        self._connections[topic] = conn
        return conn

    def _write(self, topic: str, msgtype: str, stamp_ns: int, msg: Any, latched: bool = False) -> None:
        if self._writer is None:
            raise RuntimeError("SequenceWriter used outside its with-block")
        if not self._static_written:
            self._write_tf_static(stamp_ns)
        conn = self._add(topic, msgtype, latched)
        self._writer.write(conn, int(stamp_ns), typestore().serialize_cdr(msg, msgtype))

    def _write_tf_static(self, stamp_ns: int) -> None:
        self._static_written = True
        types = typestore().types
        transforms = []
        for cam in self.cameras.values():
            qx, qy, qz, qw = cam.quaternion
            transforms.append(
                types["geometry_msgs/msg/TransformStamped"](
                    header=_header(stamp_ns, WORLD_FRAME),
                    child_frame_id=cam.frame_id,
                    transform=types["geometry_msgs/msg/Transform"](
                        translation=types["geometry_msgs/msg/Vector3"](*map(float, cam.position)),
                        rotation=types["geometry_msgs/msg/Quaternion"](float(qx), float(qy), float(qz), float(qw)),
                    ),
                )
            )
        self._write(TF_STATIC_TOPIC, TF_MESSAGE, stamp_ns, types[TF_MESSAGE](transforms=transforms), latched=True)

    def _camera_info(self, cam: Camera, stamp_ns: int) -> Any:
        types = typestore().types
        K = np.asarray(cam.K, float)
        P = np.zeros((3, 4))
        P[:, :3] = K
        return types[CAMERA_INFO](
            header=_header(stamp_ns, cam.frame_id),
            height=cam.height,
            width=cam.width,
            distortion_model="rational_polynomial" if cam.distortion.size == 8 else "plumb_bob",
            d=np.asarray(cam.distortion, float).copy(),
            k=K.ravel().copy(),
            r=np.eye(3).ravel(),
            p=P.ravel(),
            binning_x=0,
            binning_y=0,
            roi=types["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False),
        )

    # -- public writers -----------------------------------------------------------------------
    def write_frame(self, stamp_ns: int, images: dict[str, np.ndarray]) -> None:
        """One synchronised frame: an HxWx3 uint8 RGB image for every camera, plus CameraInfo."""
        where = f"{self.path}: frame {self.frames_written} (stamp {stamp_ns} ns)"
        if self._last_frame_ns is not None and stamp_ns <= self._last_frame_ns:
            raise InputError(
                f"{where}: timestamps must increase strictly, previous frame was at {self._last_frame_ns} ns"
            )
        if set(images) != set(self.cameras):
            unknown = sorted(set(images) - set(self.cameras))
            missing = sorted(set(self.cameras) - set(images))
            raise InputError(f"{where}: images for cameras {sorted(self.cameras)} expected; "
                             f"unknown {unknown}, missing {missing}")
        types = typestore().types
        for name, cam in self.cameras.items():
            rgb = _rgb_image(images[name], f"{where}: camera {name}", cam.width, cam.height)
            if self.compressed:
                ext = ".png" if self.image_format == "png" else ".jpg"
                ok, buf = cv2.imencode(ext, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
                if not ok:
                    raise InputError(f"{where}: camera {name}: {self.image_format} encoding failed")
                msg = types[COMPRESSED_IMAGE](
                    header=_header(stamp_ns, cam.frame_id),
                    format=f"rgb8; {self.image_format} compressed bgr8",
                    data=buf.ravel(),
                )
                self._write(image_topic(name, True), COMPRESSED_IMAGE, stamp_ns, msg)
            else:
                msg = types[IMAGE](
                    header=_header(stamp_ns, cam.frame_id),
                    height=cam.height,
                    width=cam.width,
                    encoding="rgb8",
                    is_bigendian=0,
                    step=3 * cam.width,
                    data=rgb.reshape(-1),
                )
                self._write(image_topic(name, False), IMAGE, stamp_ns, msg)
            self._write(camera_info_topic(name), CAMERA_INFO, stamp_ns, self._camera_info(cam, stamp_ns))
        self._last_frame_ns = int(stamp_ns)
        self.frames_written += 1

    def write_ground_truth(
        self,
        stamp_ns: int,
        markers: np.ndarray,
        joint_names: list[str] | None = None,
        joint_angles: np.ndarray | None = None,
    ) -> None:
        """Ground-truth 3D markers (13, 3) in the world frame (m), order MARKER_NAMES; joint angles (rad)."""
        markers = np.asarray(markers, float)
        if markers.shape != (len(MARKER_NAMES), 3) or not np.all(np.isfinite(markers)):
            raise InputError(f"{self.path}: ground truth at {stamp_ns} ns: expected finite markers of shape (13, 3), "
                             f"got {markers.shape}")
        joint_names = list(joint_names or [])
        angles = np.asarray(joint_angles if joint_angles is not None else [], float).ravel()
        if len(joint_names) != angles.size:
            raise InputError(f"{self.path}: ground truth at {stamp_ns} ns: {len(joint_names)} joint names "
                             f"but {angles.size} joint angles")
        types = typestore().types
        Point = types["geometry_msgs/msg/Point"]
        qx, qy, qz, qw = torso_quaternion(markers)
        msg = types[BODY_POSE](
            header=_header(stamp_ns, WORLD_FRAME),
            marker_names=list(MARKER_NAMES),
            markers=[Point(*map(float, m)) for m in markers],
            torso=types["geometry_msgs/msg/Pose"](
                position=Point(*map(float, markers[0])),
                orientation=types["geometry_msgs/msg/Quaternion"](float(qx), float(qy), float(qz), float(qw)),
            ),
            joint_names=joint_names,
            joint_angles=angles.copy(),
        )
        self._write(GROUND_TRUTH_TOPIC, BODY_POSE, stamp_ns, msg)

    def write_text(self, topic: str, stamp_ns: int, text: str) -> None:
        """A std_msgs/String (e.g. a description YAML); latched in the bag metadata."""
        self._write(topic, STRING, stamp_ns, typestore().types[STRING](data=str(text)), latched=True)

    def write_occlusion_mask(self, stamp_ns: int, cam_name: str, mask: np.ndarray) -> None:
        """An HxW occlusion mask for one camera (true / nonzero = occluded) as mono8 0/255."""
        if cam_name not in self.cameras:
            raise InputError(f"{self.path}: occlusion mask for unknown camera {cam_name!r}; "
                             f"cameras are {sorted(self.cameras)}")
        cam = self.cameras[cam_name]
        mask = np.asarray(mask)
        if mask.shape != (cam.height, cam.width):
            raise InputError(f"{self.path}: occlusion mask for {cam_name}: expected shape "
                             f"({cam.height}, {cam.width}), got {mask.shape}")
        data = np.where(mask != 0, 255, 0).astype(np.uint8).reshape(-1)
        msg = typestore().types[IMAGE](
            header=_header(stamp_ns, cam.frame_id), height=cam.height, width=cam.width, encoding="mono8",
            is_bigendian=0, step=cam.width, data=data,
        )
        self._write(occlusion_mask_topic(cam_name), IMAGE, stamp_ns, msg)

    def write_message(self, topic: str, msgtype: str, stamp_ns: int, msg: Any, latched: bool = False) -> None:
        """Any message of a type known to ``typestore()`` (a rosbags message object)."""
        if msgtype not in typestore().types:
            raise InputError(f"{self.path}: topic {topic}: unknown message type {msgtype!r}")
        self._write(topic, msgtype, stamp_ns, msg, latched)


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------
def open_reader(path: str | Path) -> Reader:
    """An open rosbags Reader; InputError naming the bag if it is missing, corrupt or unreadable."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: bag not found")
    try:
        reader = Reader(path)
        reader.open()
    except FileNotFoundError as exc:
        raise InputError(f"{path}: not a rosbag2 bag ({exc})") from None
    except ReaderError as exc:
        raise InputError(f"{path}: not a readable rosbag2 bag ({exc})") from None
    except _BAG_DATA_ERRORS as exc:
        raise InputError(f"{path}: corrupt or truncated bag ({type(exc).__name__}: {exc})") from None
    return reader


def iter_messages(
    reader: Reader, path: str | Path, connections: Iterable[Connection] = ()
) -> Iterator[tuple[Connection, int, bytes]]:
    """reader.messages() with damaged-file errors turned into InputError naming the bag."""
    try:
        yield from reader.messages(connections=list(connections))
    except _BAG_DATA_ERRORS as exc:
        raise InputError(f"{path}: corrupt or truncated bag ({type(exc).__name__}: {exc})") from None


def camera_from_messages(info: Any, transform: Any | None, name: str, source: str = "") -> Camera:
    """A validated Camera (``vision.camera.camera_from_info``) from a CameraInfo and the world -> optical-frame
    TransformStamped of /tf_static; errors name ``source`` (the bag) and the topic."""
    prefix = f"{source}: " if source else ""
    if transform is None:
        raise InputError(f"{prefix}{TF_STATIC_TOPIC}: no transform {WORLD_FRAME} -> {name}_optical_frame (camera pose)")
    t, q = transform.transform.translation, transform.transform.rotation
    return camera_from_info(name, info, (t.x, t.y, t.z), (q.x, q.y, q.z, q.w), f"{prefix}{camera_info_topic(name)}",
                            f"{prefix}{TF_STATIC_TOPIC} ({WORLD_FRAME} -> {name}_optical_frame)")


class SequenceReader:
    """Read a sequence bag (context manager). See the module docstring for the topics."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._reader: Reader | None = None
        self._cameras: list[Camera] | None = None
        self._frame_stamps: np.ndarray | None = None

    def __enter__(self) -> "SequenceReader":
        self._reader = open_reader(self.path)
        return self

    def __exit__(self, *exc: object) -> None:
        reader, self._reader = self._reader, None
        if reader is not None:
            reader.close()

    # -- low level ----------------------------------------------------------------------------
    @property
    def reader(self) -> Reader:
        if self._reader is None:
            raise RuntimeError("SequenceReader used outside its with-block")
        return self._reader

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> message type."""
        return {c.topic: c.msgtype for c in self.reader.connections}

    def connections(self, topic: str) -> list[Connection]:
        return [c for c in self.reader.connections if c.topic == topic]

    def messages(self, topics: Iterable[str]) -> Iterator[tuple[str, str, int, Any]]:
        """(topic, msgtype, log time ns, deserialised message) for the given topics, in time order."""
        topics = set(topics)
        conns = [c for c in self.reader.connections if c.topic in topics]
        if not conns:
            return
        ts = typestore()
        for conn, log_ns, raw in iter_messages(self.reader, self.path, conns):
            try:
                msg = ts.deserialize_cdr(raw, conn.msgtype)
            except KeyError:
                raise InputError(f"{self.path}: topic {conn.topic}: unknown message type {conn.msgtype}") from None
            except Exception as exc:  # rosbags raises assorted errors on malformed CDR
                raise InputError(f"{self.path}: topic {conn.topic}: cannot deserialise {conn.msgtype} "
                                 f"({type(exc).__name__}: {exc})") from None
            yield conn.topic, conn.msgtype, log_ns, msg

    def first_message(self, topic: str) -> Any | None:
        """The first message on ``topic`` (deserialised), or None."""
        return next((m for _, _, _, m in self.messages([topic])), None)

    # -- cameras ------------------------------------------------------------------------------
    @property
    def camera_names(self) -> list[str]:
        """Cameras with a ``/<cam>/camera_info`` topic (sorted)."""
        return sorted(
            c.topic[1: -len("/camera_info")]
            for c in self.reader.connections
            if c.topic.endswith("/camera_info") and c.msgtype == CAMERA_INFO and c.topic.count("/") == 2
        )

    def image_topic_of(self, cam: str) -> tuple[str, str] | None:
        """(topic, msgtype) of a camera's images, raw preferred, or None."""
        topics = self.topics
        for topic, msgtype in ((image_topic(cam, False), IMAGE), (image_topic(cam, True), COMPRESSED_IMAGE)):
            if topics.get(topic) == msgtype:
                return topic, msgtype
        return None

    def first_image_error(self, cam: str) -> InputError | None:
        """Why camera ``cam``'s first image cannot be decoded (``vision.decode``'s error, naming the topic), or
        None: it can, or there is none."""
        found = self.image_topic_of(cam)
        msg = None if found is None else self.first_message(found[0])
        if msg is None:
            return None
        try:
            decode_image(msg, found[0])
        except InputError as exc:
            return exc
        return None

    def camera_transforms(self) -> dict[str, Any]:
        """Child frame -> TransformStamped from /tf_static with parent ``world`` (last one wins)."""
        found: dict[str, Any] = {}
        for _, _, _, msg in self.messages([TF_STATIC_TOPIC]):
            for tf in msg.transforms:
                if tf.header.frame_id.lstrip("/") == WORLD_FRAME:
                    found[tf.child_frame_id.lstrip("/")] = tf
        return found

    @property
    def cameras(self) -> list[Camera]:
        """Cameras from camera_info + /tf_static; InputError naming the bag and what is missing."""
        if self._cameras is None:
            names = self.camera_names
            if not names:
                raise InputError(f"{self.path}: no camera found: expected /<cam>/camera_info topics of type "
                                 f"{CAMERA_INFO}; topics are {sorted(self.topics)}")
            transforms = self.camera_transforms()
            cameras = []
            for name in names:
                info = self.first_message(camera_info_topic(name))
                if info is None:
                    raise InputError(f"{self.path}: topic {camera_info_topic(name)} holds no messages")
                tf = transforms.get(f"{name}_optical_frame")
                if tf is None:
                    raise InputError(f"{self.path}: {TF_STATIC_TOPIC} has no transform {WORLD_FRAME} -> "
                                     f"{name}_optical_frame (pose of camera {name})")
                if self.image_topic_of(name) is None:
                    raise InputError(f"{self.path}: camera {name} has no images: expected {image_topic(name, False)} "
                                     f"({IMAGE}) or {image_topic(name, True)} ({COMPRESSED_IMAGE})")
                cameras.append(camera_from_messages(info, tf, name, str(self.path)))
            self._cameras = cameras
        return self._cameras

    # -- frames -------------------------------------------------------------------------------
    def _image_topics(self) -> dict[str, str]:
        topics = {}
        for cam in self.cameras:
            topic, _ = self.image_topic_of(cam.name)  # type: ignore[misc]  # cameras checked it exists
            topics[topic] = cam.name
        return topics

    def frames(self, decode: bool = True) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
        """(stamp_ns, {cam: HxWx3 uint8 RGB}) per frame, in stamp order; all cameras share stamps.

        InputError if stamps do not increase per camera or a camera misses a frame.
        """
        topic_cam = self._image_topics()
        n_cams = len(topic_cam)
        pending: dict[int, dict[str, np.ndarray]] = {}
        last: dict[str, int] = {}
        last_emitted: int | None = None
        for topic, _, _, msg in self.messages(topic_cam):
            cam = topic_cam[topic]
            stamp = stamp_ns_of(msg.header)
            if cam in last and stamp <= last[cam]:
                raise InputError(f"{topic}: image stamps must increase strictly: {stamp} ns after {last[cam]} ns")
            last[cam] = stamp
            if last_emitted is not None and stamp <= last_emitted:
                raise InputError(f"{topic}: image at {stamp} ns arrives after frame {last_emitted} ns was complete")
            pending.setdefault(stamp, {})[cam] = decode_image(msg, topic) if decode else msg
            if len(pending[stamp]) == n_cams:
                for older in sorted(s for s in pending if s < stamp):
                    self._incomplete(older, pending[older], topic_cam)
                last_emitted = stamp
                yield stamp, pending.pop(stamp)
        for older in sorted(pending):
            self._incomplete(older, pending[older], topic_cam)

    def _incomplete(self, stamp: int, have: dict[str, Any], topic_cam: dict[str, str]) -> None:
        missing = [t for t, c in topic_cam.items() if c not in have]
        raise InputError(f"{self.path}: frame at {stamp} ns has no image on {', '.join(missing)} "
                         "(all cameras must share the frame stamps)")

    @property
    def frame_stamps(self) -> np.ndarray:
        """Frame stamps (F,) int64 ns: the header stamps of the first camera's images."""
        if self._frame_stamps is None:
            topic, _ = self.image_topic_of(self.cameras[0].name)  # type: ignore[misc]
            stamps = [stamp_ns_of(m.header) for _, _, _, m in self.messages([topic])]
            self._frame_stamps = np.asarray(stamps, np.int64)
        return self._frame_stamps

    # -- extras -------------------------------------------------------------------------------
    def ground_truth(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(stamps (F,) int64 ns, markers (F, 13, 3) m, order MARKER_NAMES) or None if absent."""
        stamps, frames = [], []
        for topic, _, _, msg in self.messages([GROUND_TRUTH_TOPIC]):
            names = list(msg.marker_names)
            missing = [n for n in MARKER_NAMES if n not in names]
            if missing or len(msg.markers) != len(names):
                raise InputError(f"{topic}: BodyPose needs markers {list(MARKER_NAMES)}; missing {missing}, "
                                 f"{len(names)} names for {len(msg.markers)} points")
            points = np.array([[p.x, p.y, p.z] for p in msg.markers])
            frames.append(points[[names.index(n) for n in MARKER_NAMES]])
            stamps.append(stamp_ns_of(msg.header))
        if not stamps:
            return None
        return np.asarray(stamps, np.int64), np.stack(frames)

    def text(self, topic: str) -> str | None:
        """The first std_msgs/String on ``topic`` (e.g. a description YAML), or None."""
        if topic not in self.topics:
            return None
        if self.topics[topic] != STRING:
            raise InputError(f"{self.path}: topic {topic} holds {self.topics[topic]}, expected {STRING}")
        msg = self.first_message(topic)
        return None if msg is None else str(msg.data)

    def occlusion_masks(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Camera -> (stamps (F,) int64 ns, masks (F, H, W) bool, true = occluded); cameras without masks absent."""
        result: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for cam in self.camera_names:
            topic = occlusion_mask_topic(cam)
            if self.topics.get(topic) != IMAGE:
                continue
            stamps, masks = [], []
            for _, _, _, msg in self.messages([topic]):
                masks.append(decode_mono8(msg, topic) > 127)
                stamps.append(stamp_ns_of(msg.header))
            if stamps:
                result[cam] = (np.asarray(stamps, np.int64), np.stack(masks))
        return result


def copy_bag(source: str | Path, destination: str | Path, cameras: Iterable[str], start_ns: int | None = None,
             descriptions: bool = True, storage: str = "mcap") -> int:
    """Copy a sequence bag's messages as they are stored (no decoding): per-camera topics (``/<cam>/...``) of
    ``cameras`` only, every other topic but the start and body descriptions unless ``descriptions``; from
    ``start_ns`` on (None: all), latched topics whatever their stamp (moved to ``start_ns`` if earlier).
    Returns the number of messages written; InputError naming the bags on a missing camera or a bad bag."""
    source, destination = Path(source), Path(destination)
    keep = set(cameras)
    with SequenceReader(source) as reader:
        known = set(reader.camera_names)
        if not keep <= known:
            raise InputError(f"{source}: no camera {', '.join(sorted(keep - known))}; cameras are {sorted(known)}")
        if destination.exists():
            raise InputError(f"{destination}: output bag exists already; choose a new path or remove it")

        def wanted(connection: Connection) -> bool:
            owner = connection.topic.split("/")[1] if connection.topic.count("/") >= 2 else ""
            if owner in known and owner not in keep:
                return False
            return descriptions or connection.topic not in (START_DESCRIPTION_TOPIC, BODY_DESCRIPTION_TOPIC)

        connections = [c for c in reader.reader.connections if wanted(c)]
        writer = Writer(destination, version=9, storage_plugin=STORAGES[storage])
        written = 0
        try:
            writer.open()
            out = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=typestore(),
                                               offered_qos_profiles=list(c.ext.offered_qos_profiles))
                   for c in connections}
            for connection, stamp, raw in iter_messages(reader.reader, source, connections):
                if start_ns is not None and stamp < start_ns:
                    if not is_latched(connection):
                        continue
                    stamp = start_ns
                writer.write(out[connection.id], stamp, raw)
                written += 1
        except BaseException:
            writer.abort()
            shutil.rmtree(destination, ignore_errors=True)
            raise
        writer.close()
    return written
