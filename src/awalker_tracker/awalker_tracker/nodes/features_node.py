"""Features node: one camera's images -> per-frame appearance ratio maps and grid flow.

Subscribes (camera ``<cam>`` from the ``camera_name`` parameter):
- ``/<cam>/image_raw`` (sensor_msgs/Image: rgb8, bgr8, mono8, rgba8, bgra8, mono16) and
  ``/<cam>/image_raw/compressed`` (sensor_msgs/CompressedImage: JPEG or PNG, told by the data;
  ``vision.decode``), sensor-data QoS
  (a best-effort reader also receives the replay's reliable publications);
- optional ``/<cam>/occlusion_mask`` (mono8, 255 = occluded; applied to the frame with the same
  stamp: its pixels get ratio 0 and its flow cells are invalid). When the camera has masks (a
  publisher on the topic, or a mask seen before), an image whose mask has not arrived yet is
  held until it does (replay publishes a frame's mask just after its image), for at most
  ``mask_wait_s``; images are processed in the order they came, each once its own mask is
  there; an image that gets no mask is processed without one, logged and counted
  (``stats.frames_without_mask``). Whether a mask came in time does not depend on how busy the
  machine is: the wait's end is decided after the messages already delivered are handled. And ``/<cam>/foreground_labels`` (mono8 class label
  image for learning the foreground: 0 = none, k = 1 + index into PART_CLASSES);
- ``/awalker/start_description`` (latched std_msgs/String), or the ``start_description`` YAML
  file parameter: the frames before its ``frame`` are background-only (``background_frames`` =
  -1, the default); with ``use_start_description`` false neither is used (automatic start: the
  background is learned robustly from the first ``median_frames`` frames, and again from more
  frames as they come (``vision.features``));
- ``/awalker/body_description`` (latched), or the ``body_description`` file parameter: body
  sizes (start-pose projection, bands);
- ``/<cam>/camera_info`` and ``/<cam>/camera_pose`` (latched geometry_msgs/PoseStamped, as the
  replay publishes it): with the start description, the foreground mixtures are learned from
  the body projected at the start pose (``start_pose_labels`` parameter), foreground pixels it
  misses labelled by height bands; without them, by height bands alone.
Publishes ``/<cam>/features`` (awalker_msgs/ImageFeatures, reliable, depth 10), stamped with
the image stamp, for every image it can decode — also during background learning (zero maps),
so lockstep replay never waits. A frame's features are published, in the frames' order, once its
flow is estimated on the extractor's thread (``FeatureExtractor.submit``), while the node decodes
the next image and makes its maps; an unexpected error there is raised in the executor's thread.
An image that cannot be decoded (or used: a size other than the first frames') is logged with the topic
and counted (``stats.undecodable``), and its frame's features carry no evidence: zero maps, no flow
(``FeatureExtractor.submit_blank``), so the tracker still counts the frame and acknowledges it. Images with
out-of-order stamps are logged, counted (``stats.skipped``) and skipped.

Message conversions (``features_to_msg``, ``features_from_msg``) are plain functions the tracker side
reuses; images are decoded by ``vision.decode``, as the bag reader decodes them.
"""
from __future__ import annotations

import array
import sys
import threading
import time
from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import rclpy
from awalker_msgs.msg import FlowGrid as FlowGridMsg
from awalker_msgs.msg import ImageFeatures
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header, String

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import PART_CLASSES, BodyDescription
from awalker_tracker.model.walker import LEFT
from awalker_tracker.nodes.base import AwalkerNode, NodeParameter, declare_parameters
from awalker_tracker.nodes.messages import camera_from_msgs, stamp_to_ns
from awalker_tracker.nodes.spin import run_node
from awalker_tracker.vision.decode import decode_image, decode_mono8
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor, FrameFeatures
from awalker_tracker.vision.flow import FlowConfig, FlowGrid
from awalker_tracker.vision.foreground import start_pose_labels

START_TOPIC = "/awalker/start_description"
BODY_TOPIC = "/awalker/body_description"


# ---- message conversion -------------------------------------------------------------------
def _floats(values: np.ndarray) -> array.array:
    """float32 array.array of ``values`` (one copy)."""
    out = array.array("f")
    out.frombytes(np.ascontiguousarray(values, np.float32).reshape(-1).view(np.uint8))
    return out


def _flags(values: np.ndarray) -> array.array:
    """uint8 array.array (0/1) of a bool array, row-major."""
    return array.array("B", np.ascontiguousarray(values, np.uint8).tobytes())


def features_to_msg(features: FrameFeatures, hdr: Header, camera_name: str) -> ImageFeatures:
    """awalker_msgs/ImageFeatures of one frame (``hdr``: image stamp, optical frame id)."""
    flow = features.flow
    rows, cols = flow.shape
    grid = FlowGridMsg(rows=rows, cols=cols, cell_size=int(flow.cell_size))
    grid.center_x = _floats(flow.centers[..., 0])
    grid.center_y = _floats(flow.centers[..., 1])
    grid.flow_x = _floats(flow.flow[..., 0])
    grid.flow_y = _floats(flow.flow[..., 1])
    grid.covariance = _floats(flow.covariance)
    grid.valid = _flags(flow.valid)
    h, w = features.map_shape
    msg = ImageFeatures(header=hdr, camera_name=camera_name, image_width=int(features.image_width),
                        image_height=int(features.image_height), part_classes=list(features.classes),
                        map_width=w, map_height=h, downsample=int(features.downsample), flow=grid)
    msg.log_likelihood_ratio = _floats(features.llr)
    if features.occlusion is not None:
        msg.occlusion_map = _flags(features.occlusion)
    return msg


def features_from_msg(msg: ImageFeatures) -> FrameFeatures:
    """FrameFeatures from awalker_msgs/ImageFeatures; InputError on inconsistent sizes or NaN."""
    where = f"ImageFeatures of camera {msg.camera_name!r}"
    classes = tuple(msg.part_classes)
    h, w, d = int(msg.map_height), int(msg.map_width), int(msg.downsample)
    llr = np.asarray(msg.log_likelihood_ratio, np.float32)
    if d < 1 or llr.size != len(classes) * h * w:
        raise InputError(f"{where}: {llr.size} ratios for {len(classes)} classes x {h} x {w} (downsample {d})")
    g = msg.flow
    rows, cols, n = int(g.rows), int(g.cols), int(g.rows) * int(g.cols)
    arrays = [np.asarray(a, np.float32) for a in (g.center_x, g.center_y, g.flow_x, g.flow_y)]
    cov = np.asarray(g.covariance, np.float32)
    valid = np.asarray(g.valid, np.uint8)
    if any(a.size != n for a in arrays) or cov.size != 4 * n or valid.size != n or int(g.cell_size) < 1:
        raise InputError(f"{where}: flow grid arrays do not match {rows} x {cols} cells")
    if not (np.all(np.isfinite(llr)) and all(np.all(np.isfinite(a)) for a in arrays) and np.all(np.isfinite(cov))):
        raise InputError(f"{where}: NaN or infinity in the maps or the flow grid")
    flow = FlowGrid(np.stack(arrays[:2], -1).reshape(rows, cols, 2), np.stack(arrays[2:], -1).reshape(rows, cols, 2),
                    cov.reshape(rows, cols, 2, 2), valid.reshape(rows, cols) > 0, int(g.cell_size))
    occluded = np.asarray(msg.occlusion_map, np.uint8)
    if occluded.size not in (0, h * w):
        raise InputError(f"{where}: occlusion map of {occluded.size} pixels for a {h} x {w} map (expected {h * w} or none)")
    occlusion = occluded.reshape(h, w) > 0 if occluded.size else None
    return FrameFeatures(classes, llr.reshape(len(classes), h, w), d, int(msg.image_width), int(msg.image_height), flow,
                         occlusion)


# ---- node -----------------------------------------------------------------------------------
@dataclass
class FeatureNodeStats:
    frames: int = 0
    skipped: int = 0
    undecodable: int = 0          # images that could not be decoded: published as frames without evidence
    decoded: int = 0              # images decoded and used
    first_undecodable: str = ""   # why the first undecodable image could not be decoded
    seconds: float = 0.0
    foreground_from: str = ""     # "start pose", "label image" or "height bands" once learned
    background_from: str = ""     # how the background model was learned, once it was
    frames_without_mask: int = 0  # images processed without their occlusion mask on a camera that has masks


#: The node's ROS parameters (declared from here; listed by ``awalker_features --help``).
PARAMETERS = (
    NodeParameter("camera_name", "", "camera name: /<camera_name>/image_raw[/compressed] (required)"),
    NodeParameter("downsample", FeatureConfig.downsample,
                  "likelihood-ratio map pixel = downsample x downsample image pixels (`awalker track`: "
                  "vision.features.map_downsample, 2 at 320x240 with two cameras or more)"),
    NodeParameter("flow_cell_size", 16, "flow grid cell side (px)"),
    NodeParameter("flow_scale", 1.0, "dense flow computed at this image scale (0-1]"),
    NodeParameter("flow_floor_std", 1.0, "px added to each flow cell's standard deviation"),
    NodeParameter("background_frames", -1, "background-only frames at the start; -1: the start description's "
                  "frame; 0: none (robust background from the walk itself)"),
    NodeParameter("median_frames", FeatureConfig.median_frames, "frames (at 30 per second of the images' stamps) "
                  "the robust background is first learned from when none are known"),
    NodeParameter("outlier_probability", 0.02, "uniform outlier share of the appearance densities"),
    NodeParameter("llr_clip", 25.0, "bound on each pixel's log-likelihood ratio"),
    NodeParameter("adapt_rate", 0.0, "background adaptation rate per frame (0 = frozen)"),
    NodeParameter("compensate_gain", True, "divide out global per-channel lighting changes"),
    NodeParameter("start_pose_labels", True, "learn the foreground from the body projected at the start pose "
                  "(needs camera_info and camera_pose)"),
    NodeParameter("opencv_threads", 1, "OpenCV worker threads (process-wide; 1 is fastest when cores are shared, "
                  "e.g. one features node per camera; 0 = OpenCV default)"),
    NodeParameter("verbose", False, "log model learning to stderr"),
    NodeParameter("mask_wait_s", 0.25, "s an image waits for its occlusion mask when the camera has masks"),
    NodeParameter("start_description", "", "start YAML (background-only frames, start pose); empty: the "
                  "/awalker/start_description topic"),
    NodeParameter("body_description", "", "body YAML; empty: the /awalker/body_description topic or the default body"),
    NodeParameter("use_start_description", True, "false: no start description (the tracker finds the person "
                  "itself): robust background, foreground from height bands"),
)


class FeatureNode(AwalkerNode):
    """Image features for one camera (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        camera = next((p.value for p in kwargs.get("parameter_overrides", []) if p.name == "camera_name"), None)
        super().__init__(f"awalker_features_{camera}" if camera else "awalker_features", **kwargs)

        v = declare_parameters(self, PARAMETERS)
        self.camera_name = str(v["camera_name"])
        downsample, cell, scale, floor = v["downsample"], v["flow_cell_size"], v["flow_scale"], v["flow_floor_std"]
        self.background_param = int(v["background_frames"])
        median, outlier, clip, adapt = v["median_frames"], v["outlier_probability"], v["llr_clip"], v["adapt_rate"]
        gain = v["compensate_gain"]
        self.use_start_pose = bool(v["start_pose_labels"])
        threads = int(v["opencv_threads"])
        self.verbose = bool(v["verbose"])
        self.mask_wait_s = float(v["mask_wait_s"])
        start_path, body_path = str(v["start_description"]), str(v["body_description"])
        use_start = bool(v["use_start_description"])
        if not self.camera_name:
            raise InputError("parameter 'camera_name' is required (e.g. --ros-args -p camera_name:=cam0)")
        try:
            self.config = FeatureConfig(
                downsample=int(downsample), background_frames=max(self.background_param, 0),
                median_frames=int(median), outlier_probability=float(outlier), llr_clip=float(clip),
                adapt_rate=float(adapt), compensate_gain=bool(gain),
                flow=FlowConfig(cell_size=int(cell), scale=float(scale), floor_std=float(floor)))
        except ValueError as exc:
            raise InputError(f"awalker_features ({self.camera_name}): {exc}") from None
        if threads > 0:
            cv2.setNumThreads(threads)
        from awalker_tracker.inference.filter_model import StartDescription

        self.extractor = FeatureExtractor(self.config, body=BodyDescription.from_yaml(body_path) if body_path else None,
                                          verbose=self.verbose)
        self.stats = FeatureNodeStats()
        self._last_stamp = -1
        self._masks: dict[int, np.ndarray] = {}
        self._masks_seen = False
        # images waiting for their masks, oldest first: (message, topic, stamp ns, monotonic deadline s)
        self._held: deque[tuple[Image | CompressedImage, str, int, float]] = deque()
        self._hold_timer: Any = None
        self._wait_over = self.create_guard_condition(lambda: self._release_held(overdue=True))
        self._failure: Exception | None = None
        self._skip_lock = threading.Lock()
        self._failed = self.create_guard_condition(self._fail)
        self._labels: np.ndarray | None = None
        self._start: Any = None
        self._info: CameraInfo | None = None
        self._pose: PoseStamped | None = None
        cam = self.camera_name
        self.image_topic = f"/{cam}/image_raw"
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Image, self.image_topic, lambda m: self._on_image(m, self.image_topic),
                                 qos_profile_sensor_data)
        self.create_subscription(CompressedImage, f"{self.image_topic}/compressed",
                                 lambda m: self._on_image(m, f"{self.image_topic}/compressed"), qos_profile_sensor_data)
        self.create_subscription(Image, f"/{cam}/occlusion_mask", self._on_mask, QoSProfile(depth=30))
        self.create_subscription(Image, f"/{cam}/foreground_labels", self._on_labels, latched)
        if start_path and use_start:
            self._use_start(StartDescription.from_yaml(start_path))
        elif use_start:
            self.create_subscription(String, START_TOPIC, self._on_start, latched)
        self.create_subscription(CameraInfo, f"/{cam}/camera_info", self._on_info, reliable)
        self.create_subscription(PoseStamped, f"/{cam}/camera_pose", self._on_pose, latched)
        if not body_path:
            self.create_subscription(String, BODY_TOPIC, self._on_body, latched)
        self.publisher = self.create_publisher(ImageFeatures, f"/{cam}/features", reliable)

    # -- side inputs ------------------------------------------------------------------------
    def _on_start(self, msg: String) -> None:
        from awalker_tracker.inference.filter_model import StartDescription

        try:
            start = StartDescription.from_yaml_text(msg.data, START_TOPIC)
        except InputError as exc:
            self.get_logger().error(f"{exc}; background frames unknown")
            return
        self._use_start(start)

    def _use_start(self, start: Any) -> None:
        """The start description: its frame counts the background-only frames; its pose labels the foreground."""
        self._start = start
        if self.background_param < 0:
            self.extractor.set_background_frames(start.frame)

    def use_background(self, background: Any, source: str) -> None:
        """A background model learned beforehand (``FeatureExtractor.use_background``), ``source`` saying from
        what (``stats.background_from``); before the first image."""
        self.extractor.use_background(background)
        self.stats.background_from = source

    def _on_info(self, msg: CameraInfo) -> None:
        self._info = msg

    def _on_pose(self, msg: PoseStamped) -> None:
        self._pose = msg

    def _start_labels(self, rgb: np.ndarray) -> np.ndarray | None:
        """Class labels of the body at the start pose, if this frame learns the foreground and
        the start, the camera_info and the camera pose are known."""
        if not (self.use_start_pose and self._labels is None and self.extractor.learns_foreground_next
                and self._start is not None and self._info is not None and self._pose is not None):
            return None
        try:
            camera = camera_from_msgs(self.camera_name, self._info, self._pose)
        except InputError as exc:
            self.get_logger().error(f"{exc}; learning the foreground from height bands")
            return None
        if (camera.height, camera.width) != rgb.shape[:2]:
            self.get_logger().error(f"/{self.camera_name}/camera_info says {camera.width}x{camera.height}, images are "
                                    f"{rgb.shape[1]}x{rgb.shape[0]}; learning the foreground from height bands")
            return None
        s = self._start
        labels = start_pose_labels(self.extractor.body, camera, s.position, s.heading,
                                   s.step_length_for(self.extractor.body.walker_params()),
                                   LEFT if s.stance_leg is None else s.stance_leg)
        if self.verbose:
            print(f"features {self.camera_name}: start pose covers {np.count_nonzero(labels >= 0)} px",
                  file=sys.stderr, flush=True)
        return labels

    def _on_body(self, msg: String) -> None:
        try:
            self.extractor.body = BodyDescription.from_yaml_text(msg.data, BODY_TOPIC)
        except InputError as exc:
            self.get_logger().error(f"{exc}; using the default body proportions")

    def _on_mask(self, msg: Image) -> None:
        topic = f"/{self.camera_name}/occlusion_mask"
        stamp = stamp_to_ns(msg.header.stamp)
        self._masks_seen = True
        try:
            self._masks[stamp] = decode_mono8(msg, topic)
        except InputError as exc:
            self.get_logger().error(str(exc))
        while len(self._masks) > 30:
            self._masks.pop(min(self._masks))
        self._release_held()

    def _on_labels(self, msg: Image) -> None:
        try:
            labels = decode_mono8(msg, f"/{self.camera_name}/foreground_labels").astype(np.int16) - 1
        except InputError as exc:
            self.get_logger().error(str(exc))
            return
        if labels.max() >= len(PART_CLASSES):
            self.get_logger().error(f"/{self.camera_name}/foreground_labels: values must be 0..{len(PART_CLASSES)}")
            return
        self._labels = labels

    # -- images -----------------------------------------------------------------------------
    def _expects_masks(self) -> bool:
        return self._masks_seen or self.count_publishers(f"/{self.camera_name}/occlusion_mask") > 0

    def _on_image(self, msg: Image | CompressedImage, topic: str) -> None:
        """Process the image now, or hold it until its occlusion mask arrives (see the module docstring)."""
        stamp = stamp_to_ns(msg.header.stamp)
        if not self._held and (stamp in self._masks or self.mask_wait_s <= 0 or not self._expects_masks()):
            self._process(msg, topic)
            return
        self._held.append((msg, topic, stamp, time.monotonic() + self.mask_wait_s))
        self._release_held()

    def _release_held(self, overdue: bool = False) -> None:
        """Process held images, oldest first, while the oldest has its mask (with ``overdue``: or its
        wait is over), then time the wait of the oldest still held."""
        if self._hold_timer is not None:
            self.destroy_timer(self._hold_timer)
            self._hold_timer = None
        now = time.monotonic()
        while self._held:
            msg, topic, stamp, deadline = self._held[0]
            if stamp not in self._masks and not (overdue and now >= deadline):
                break
            self._held.popleft()
            if stamp not in self._masks:
                self.stats.frames_without_mask += 1
                self.get_logger().warning(f"/{self.camera_name}/occlusion_mask: no mask for the image at {stamp} ns "
                                          f"within {self.mask_wait_s} s; its features ignore occlusion")
            self._process(msg, topic)
        if self._held:
            self._hold_timer = self.create_timer(max(self._held[0][3] - now, 1e-3), self._on_wait_over)

    def _on_wait_over(self) -> None:
        """The oldest held image's wait is over. An executor that was kept from running sees this timer and
        that image's mask ready together and runs timers first: the guard condition decides after the
        subscriptions (rclpy runs a node's timers, then its subscriptions, then its guard conditions)."""
        self.destroy_timer(self._hold_timer)
        self._hold_timer = None
        self._wait_over.trigger()

    def _process(self, msg: Image | CompressedImage, topic: str) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        started = time.perf_counter()
        if stamp <= self._last_stamp:
            self._skip(f"{topic}: stamp {stamp} ns is not after the previous frame's {self._last_stamp} ns")
            return
        try:
            rgb = decode_image(msg, topic)
            mask = self._masks.pop(stamp, None)
            start_labels = self._start_labels(rgb)
            learned = self.extractor.foreground is not None
            had_background = self.extractor.background is not None
            if start_labels is not None:
                pending = self.extractor.submit(rgb, mask, start_labels, fill_with_bands=True, stamp_ns=stamp)
            else:
                pending = self.extractor.submit(rgb, mask, self._labels, stamp_ns=stamp)
            self.stats.decoded += 1
            if not had_background and self.extractor.background is not None:
                frames = self.extractor.frame_index - 1
                self.stats.background_from = (
                    f"{frames} background-only frames (start description)" if self.extractor.background_frames > 0
                    else f"robust fit (densest colour per pixel) of frames 0-{frames}, refitted "
                    f"after {list(self.config.refit_frames)} frames at 30 per second")
            if not learned and self.extractor.foreground is not None:
                self.stats.foreground_from = ("start pose" if start_labels is not None else
                                              "label image" if self._labels is not None else "height bands")
                self.get_logger().info(f"{self.camera_name}: background from {self.stats.background_from}, "
                                       f"foreground learned at frame {self.extractor.frame_index - 1} "
                                       f"(foreground labels: {self.stats.foreground_from})")
        except (InputError, ValueError) as exc:
            # (the decoder's errors name the topic already)
            pending = self._blank(f"{exc if isinstance(exc, InputError) else f'{topic}: {exc}'} (image at {stamp} ns)")
            if pending is None:
                return
        self._last_stamp = stamp
        hdr = Header(stamp=msg.header.stamp, frame_id=msg.header.frame_id or f"{self.camera_name}_optical_frame")
        pending.add_done_callback(lambda done: self._publish(done, hdr, f"{topic} at {stamp} ns", started))

    def _blank(self, text: str) -> Future | None:
        """An image that could not be decoded: counted, logged, and a frame without evidence of the size of the
        frames before it (else the camera_info's); None (skipped) while neither size is known."""
        self.stats.undecodable += 1
        self.stats.first_undecodable = self.stats.first_undecodable or text
        size = self.extractor.image_size or (
            (int(self._info.width), int(self._info.height)) if self._info is not None and self._info.width > 0
            and self._info.height > 0 else None)
        if size is None:
            self._skip(f"{text}; no frame size known yet")
            return None
        self.get_logger().error(f"{text}; tracked without this image ({self.stats.undecodable} so far)")
        return self.extractor.submit_blank(*size)

    def _publish(self, done: Future, hdr: Header, where: str, started: float) -> None:
        """Publish a frame's features once its flow is estimated (called on the extractor's flow thread, in the
        frames' order, or at once). An unexpected error is kept and raised in the executor's thread (``_fail``)."""
        try:
            features = done.result()
            self.publisher.publish(features_to_msg(features, hdr, self.camera_name))
        except (InputError, ValueError) as exc:
            self._skip(f"{where}: {exc}")
            return
        except Exception as exc:
            self._failure = exc
            self._failed.trigger()
            return
        self.stats.frames += 1
        self.stats.seconds += time.perf_counter() - started

    def _fail(self) -> None:
        """Raise the error a frame's features met on the flow thread, here in the executor's thread."""
        raise RuntimeError(f"awalker_features ({self.camera_name}): features failed") from self._failure

    def destroy_node(self) -> None:
        """Publish what the extractor still works on, then destroy the node."""
        self.extractor.close()
        super().destroy_node()

    def _skip(self, text: str) -> None:
        with self._skip_lock:        # the executor's thread and the extractor's flow thread both skip frames
            self.stats.skipped += 1
        self.get_logger().error(f"{text}; frame skipped ({self.stats.skipped} so far)")


def main(args: list[str] | None = None) -> int:
    """Console script ``awalker_features``; exit status 2 on bad parameters."""
    return run_node("awalker_features", FeatureNode, args, parameters=PARAMETERS,
                    summary="One camera's images -> per-frame appearance likelihood-ratio maps and grid flow "
                            "on /<camera_name>/features.")

