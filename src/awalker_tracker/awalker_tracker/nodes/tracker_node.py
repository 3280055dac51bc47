"""Tracker node: per-camera image features -> particle filter -> posterior summaries.

Subscribes ``/<cam>/features`` (awalker_msgs/ImageFeatures) of every camera in the ``cameras``
parameter, pairs them by nearest stamp within ``sync_tolerance`` of a frame (``inference.sync``; a frame
missing a camera is tracked with the others, that camera's features carrying no evidence), steps the
filter and publishes ``/awalker/posterior`` (awalker_msgs/PosteriorSummary, stamped with the image
stamp). Each frame is acknowledged on ``/awalker/ack`` (std_msgs/Header with the frame's latest image
stamp) once the filter has taken it, so a lockstep replay can send the next. Because of
the look-ahead, the summary of frame t is published when frame t + tau arrives; after ``idle_flush_s``
without new frames (or on ``flush()``) the remaining frames are completed.

Cameras come from the ``calibration`` YAML or from ``/<cam>/camera_info`` + ``/<cam>/camera_pose``
(as the replay publishes them); start and body descriptions from YAML files or the latched
``/awalker/start_description`` and ``/awalker/body_description`` topics (body: default if none).
Frames that arrive before everything is known are kept and processed as soon as it is.
The filter's settings default to the ``profile`` parameter's (``inference.profiles``, as `awalker track
--profile`: ``accurate``, 15000 particles, or ``realtime``, 5000, for a live camera).
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

import rclpy
from awalker_msgs.msg import ImageFeatures, PosteriorSummary
from geometry_msgs.msg import PoseStamped
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header, String

from awalker_tracker.errors import InputError
from awalker_tracker.inference.autostart import AUTO_SPREAD, AutoStartConfig
from awalker_tracker.inference.filter_model import (
    ImageObservation, StartDescription, Tracker, TrackerConfig, TrackerModel, image_likelihood)
from awalker_tracker.inference.posterior import PosteriorSummary as CoreSummary
from awalker_tracker.inference.profiles import DEFAULT_PROFILE, PROFILES, particle_count_text, tracking_profile
from awalker_tracker.inference.recovery import RecoveryConfig
from awalker_tracker.inference.visibility import ViewConfig
from awalker_tracker.inference.smc import SMCConfig
from awalker_tracker.inference.sync import DEFAULT_TOLERANCE, StampSynchronizer
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.walker import LEG_NAMES
from awalker_tracker.nodes.base import AwalkerNode, Default, NodeParameter, declare_parameters
from awalker_tracker.nodes.features_node import features_from_msg
from awalker_tracker.nodes.messages import POSTERIOR_DEPTH, camera_from_msgs, header, stamp_to_ns, summary_to_msg
from awalker_tracker.nodes.spin import run_node

START_TOPIC = "/awalker/start_description"
BODY_TOPIC = "/awalker/body_description"


@dataclass
class _Pending:
    stamp_ns: int
    frame_index: int
    messages: tuple[Any, ...]


@dataclass
class TrackerNodeStats:
    frames_received: int = 0
    frames_tracked: int = 0
    summaries: int = 0
    steps: int = 0              # gait steps the summaries carried (PosteriorSummary.steps)
    sync_issues: list[str] = field(default_factory=list)
    seconds_in_filter: float = 0.0
    frames_skipped: int = 0     # frames that waited longer than max_lag_s, skipped to keep up (live)
    largest_lag_s: float = 0.0  # the longest a frame that was filtered had waited since its features arrived (s)


PROFILE_WHERE = "awalker_tracker: parameter 'profile'"


def _profile(field: str) -> Default:
    """The default of a setting the tracking profile gives (inference/profiles.py)."""
    shown = ", ".join(f"{name} {getattr(p, field)}" for name, p in PROFILES.items())
    return Default(lambda name: getattr(tracking_profile(str(name), PROFILE_WHERE), field),
                   f"the profile's: {shown}", "profile")


#: The node's ROS parameters (declared from here; listed by ``awalker_tracker_node --help``).
PARAMETERS = (
    NodeParameter("cameras", Parameter.Type.STRING_ARRAY, "camera names: /<cam>/features (required)"),
    NodeParameter("calibration", "", "calibration YAML; empty: camera_info + camera_pose topics"),
    NodeParameter("start_description", "", "start YAML; empty: /awalker/start_description topic"),
    NodeParameter("body_description", "", "body YAML; empty: /awalker/body_description topic or default"),
    NodeParameter("profile", DEFAULT_PROFILE, "defaults of the settings below, as `awalker track --profile` "
                  f"(inference/profiles.py): {', '.join(PROFILES)}"),
    NodeParameter("num_particles", _profile("num_particles"), "number of particles N (default: the profile's)"),
    NodeParameter("min_particles", _profile("min_particles"),
                  "adaptive particle count (KLD-sampling): the fewest a resampling may keep, at most num_particles; "
                  "0: num_particles throughout"),
    NodeParameter("lookahead", _profile("lookahead"), "look-ahead tau (frames)"),
    NodeParameter("trust", _profile("trust"), "gamma: trust in look-ahead weights when resampling"),
    NodeParameter("resample_fraction", _profile("resample_fraction"), "resample when N_eff < fraction * N"),
    NodeParameter("resampling", _profile("resampling"), "systematic | stratified | multinomial"),
    NodeParameter("seed", _profile("seed"), "random seed"),
    NodeParameter("likelihood_scale", _profile("likelihood_scale"),
                  "exponent (tempering) of the image likelihood; 0: images unused (dead reckoning)"),
    NodeParameter("leg_scale_spread", _profile("leg_scale_spread"), "spread (log, std) of the particles' leg "
                  "lengths around the body's (0: the body's own; TrackerConfig.leg_scale_spread)"),
    NodeParameter("pelvis_ceiling", TrackerConfig.pelvis_ceiling, "with at least pelvis_ceiling_min_cameras "
                  "cameras, each particle's pelvis at most its own fraction of the walker's hip height, drawn "
                  "around this, the stance knee bending (0.85-1; 1: off; TrackerConfig.pelvis_ceiling)"),
    NodeParameter("pelvis_ceiling_min_cameras", TrackerConfig.pelvis_ceiling_min_cameras,
                  "fewer cameras than this: no pelvis ceiling"),
    NodeParameter("auto_start", False, "no start description: find the walking person in the images "
                  "(inference/autostart.py)"),
    NodeParameter("follow_near", Parameter.Type.DOUBLE_ARRAY, "automatic start with several people in view: "
                  "follow the one first seen near this world ground point [x, y] (m); unset: the first seen"),
    NodeParameter("start_output", "", "write the start description used (given or found) to this YAML file; "
                  "empty: do not"),
    NodeParameter("fitted_start", "", "a start description fitted to these images before, its stance leg chosen "
                  "(`awalker fitbody`, awalker track's first pass): a start that names no stance leg (found "
                  "automatically, or 'unknown') takes its leg when it starts at the same frame; empty: none"),
    NodeParameter("estimate_body", False, "no body description: with the automatic start, scale the default body "
                  "to the person's height seen in the images"),
    NodeParameter("body_output", "", "write an estimated body description to this YAML file"),
    NodeParameter("depth_band_m", _profile("depth_band_m"), "one camera: walkers whose pelvis lies farther than "
                  "this (m) from where the blob's feet row puts the person lose weight; 0: off "
                  "(inference/recovery.py)"),
    NodeParameter("reseed_fallen", _profile("reseed_fallen"), "re-seed walkers that fall (inference/recovery.py)"),
    NodeParameter("reacquire", _profile("reacquire"), "re-acquire a lost track at the person seen in the images"),
    NodeParameter("hold_still", _profile("hold_still"),
                  "hold the walkers while the person seen in the images stands still"),
    NodeParameter("end_after_s", ViewConfig().end_after_s,
                  "end the track after the person is out of every camera's view this long (s), then look for the "
                  "next person; 0: never (inference/visibility.py)"),
    NodeParameter("max_lag_s", 0.5, "live: a frame whose features arrived longer ago than this (s) is skipped, "
                  "counted and logged, and the filter steps over it by the stamps, so the track keeps up with the "
                  "camera; 0: never skip (offline: awalker track sets 0)"),
    NodeParameter("frame_rate", 0.0, "frames/s; 0: from the first two frame stamps"),
    NodeParameter("world_frame", "world", "world frame id of the outputs"),
    NodeParameter("ack_topic", "/awalker/ack", "std_msgs/Header acks of processed frames"),
    NodeParameter("idle_flush_s", 2.0, "complete pending frames after this idle time (s)"),
    NodeParameter("sync_queue", 30, "features kept per camera while pairing cameras"),
    NodeParameter("sync_timeout_s", 2.0, "track a frame without the cameras still missing after this (s)"),
    NodeParameter("sync_tolerance", DEFAULT_TOLERANCE, "images of one frame may lie this fraction of a frame period apart "
                  "(paired by nearest stamp; 0: equal stamps only; the period from frame_rate, else the stamps)"),
)


class TrackerNode(AwalkerNode):
    """Runs the physics-based particle filter on synchronised per-camera features."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("awalker_tracker", **kwargs)

        v = declare_parameters(self, PARAMETERS)
        cameras = v["cameras"]
        self.calibration_path = v["calibration"]
        start_path, body_path = v["start_description"], v["body_description"]
        self.profile_name = str(v["profile"])
        n, tau, gamma, fraction = v["num_particles"], v["lookahead"], v["trust"], v["resample_fraction"]
        scheme, seed = v["resampling"], v["seed"]
        fewest, profile = int(v["min_particles"]), tracking_profile(self.profile_name, PROFILE_WHERE)
        if fewest == profile.min_particles:
            fewest = profile.fewest_for(n)
        elif not 0 <= fewest <= int(n):     # as awalker track --min-particles refuses it
            raise InputError(f"awalker_tracker: parameter 'min_particles' must lie in 0-num_particles ({n}), "
                             f"got {fewest}")
        self.likelihood_scale = float(v["likelihood_scale"])
        self.leg_scale_spread = float(v["leg_scale_spread"])
        self.pelvis_ceiling = float(v["pelvis_ceiling"])
        self.pelvis_ceiling_min_cameras = int(v["pelvis_ceiling_min_cameras"])
        self.auto_start = bool(v["auto_start"])
        follow = v["follow_near"]
        self.start_output = str(v["start_output"])
        fitted_start = str(v["fitted_start"])
        self.estimate_body = bool(v["estimate_body"])
        self.body_output = str(v["body_output"])
        depth_band = float(v["depth_band_m"])
        try:
            self.view = ViewConfig(end_after_s=float(v["end_after_s"]))
        except ValueError as exc:
            raise InputError(f"awalker_tracker: parameter 'end_after_s': {exc}") from None
        try:
            self.recovery = RecoveryConfig(reseed_fallen=bool(v["reseed_fallen"]), reacquire=bool(v["reacquire"]),
                                           hold_still=bool(v["hold_still"]), depth_band_m=depth_band)
        except ValueError as exc:
            raise InputError(f"awalker_tracker: parameter 'depth_band_m': {exc}") from None
        self.frame_rate = float(v["frame_rate"])
        self.max_lag_s = float(v["max_lag_s"])
        if not (np.isfinite(self.max_lag_s) and self.max_lag_s >= 0):
            raise InputError(f"awalker_tracker: parameter 'max_lag_s' must be >= 0 s, got {self.max_lag_s}")
        self._skip_logged = -np.inf     # monotonic time of the last skip logged
        self.world_frame = v["world_frame"]
        ack_topic = v["ack_topic"]
        self.idle_flush_s = float(v["idle_flush_s"])
        queue = v["sync_queue"]
        self.sync_timeout_s = float(v["sync_timeout_s"])
        sync_tolerance = float(v["sync_tolerance"])
        if not cameras:
            raise InputError("awalker_tracker: parameter 'cameras' is required (e.g. -p cameras:=[cam0])")
        try:
            self.autostart_config = AutoStartConfig(follow_near=None if not follow else tuple(float(v) for v in follow))
        except ValueError as exc:
            raise InputError(f"awalker_tracker: parameter 'follow_near': {exc}") from None
        self.camera_names = tuple(cameras)
        try:
            self.smc_config = SMCConfig(num_particles=int(n), lookahead=int(tau), trust=float(gamma),
                                        resample_fraction=float(fraction), resampling=str(scheme), seed=int(seed),
                                        min_particles=fewest)
        except ValueError as exc:
            raise InputError(f"awalker_tracker: {exc}") from None
        try:
            TrackerConfig(leg_scale_spread=self.leg_scale_spread)
        except ValueError as exc:
            raise InputError(f"awalker_tracker: parameter 'leg_scale_spread': {exc}") from None
        try:
            TrackerConfig(pelvis_ceiling=self.pelvis_ceiling, pelvis_ceiling_min_cameras=self.pelvis_ceiling_min_cameras)
        except ValueError as exc:
            raise InputError(f"awalker_tracker: parameters 'pelvis_ceiling', 'pelvis_ceiling_min_cameras': {exc}") from None
        try:
            self.sync = StampSynchronizer(self.camera_names, max_pending=int(queue), tolerance=sync_tolerance,
                                          period_ns=round(1e9 / self.frame_rate) if self.frame_rate > 0 else None)
        except ValueError as exc:
            raise InputError(f"awalker_tracker: parameters 'sync_queue', 'sync_tolerance': {exc}") from None
        self.stats = TrackerNodeStats()
        self.tracker: Tracker | None = None
        self.tracks_ended = 0                       # tracks that ended (the person left the view)
        self.ended_tracks: list[Tracker] = []       # ... kept, with keep_summaries, for their MAP trajectories
        self.summaries: list[CoreSummary] = []
        self.keep_summaries = False
        self._person_still = False     # the last summary said the person stands still (logged on change)
        self._pending: list[_Pending] = []
        self._frame_counter = 0                     # frame index = distinct stamps seen, dropped ones included
        self._arrivals: dict[int, int] = {}         # stamp -> when its features arrived (system time, ns)
        self._last_features: dict[str, Any] = {}   # camera -> its latest features (the shape of a frame it misses)
        self._first_stamps: list[int] = []
        self._last_frame_time = time.monotonic()
        self._dirty = False   # frames pushed since the last flush

        self.start = StartDescription.from_yaml(start_path) if start_path and not self.auto_start else None
        self.fitted_start = StartDescription.from_yaml(fitted_start) if fitted_start else None
        self._fitted_start_path = fitted_start
        self.start_found_automatically = False
        self._seen: deque = deque()               # frames the start finder saw (automatic start)
        self._finder: Any = None
        self.body = BodyDescription.from_yaml(body_path) if body_path else None
        self._body_from_file = bool(body_path)
        self.cameras: dict[str, Any] = {}
        if self.calibration_path:
            from awalker_tracker.vision.camera import load_calibration

            by_name = {c.name: c for c in load_calibration(self.calibration_path)}
            missing = [c for c in self.camera_names if c not in by_name]
            if missing:
                raise InputError(f"{self.calibration_path}: no camera(s) {', '.join(missing)} "
                                 f"(has {', '.join(by_name)})")
            self.cameras = {c: by_name[c] for c in self.camera_names}
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._infos: dict[str, CameraInfo] = {}
        self._poses: dict[str, PoseStamped] = {}
        self._camera_errors: dict[str, str] = {}    # camera -> the last error its camera_info + camera_pose gave
        if not self.cameras:
            for cam in self.camera_names:
                self.create_subscription(CameraInfo, f"/{cam}/camera_info",
                                         lambda m, c=cam: self._on_camera_info(c, m), reliable)
                self.create_subscription(PoseStamped, f"/{cam}/camera_pose",
                                         lambda m, c=cam: self._on_camera_pose(c, m), latched)
        if self.start is None and not self.auto_start:
            self.create_subscription(String, START_TOPIC, self._on_start, latched)
        if self.body is None:
            self.create_subscription(String, BODY_TOPIC, self._on_body, latched)
        self.posterior_pub = self.create_publisher(PosteriorSummary, "/awalker/posterior", QoSProfile(
            depth=POSTERIOR_DEPTH, reliability=ReliabilityPolicy.RELIABLE))
        self.ack_pub = self.create_publisher(Header, ack_topic, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        for cam in self.camera_names:
            self.create_subscription(ImageFeatures, f"/{cam}/features",
                                     lambda m, info, c=cam: self._on_features(c, m, info), QoSProfile(depth=100))
        self.create_timer(0.2, self._on_timer)

    # -- inputs ----------------------------------------------------------------------------
    def _on_camera_info(self, cam: str, msg: CameraInfo) -> None:
        self._infos[cam] = msg
        self._update_cameras()

    def _on_camera_pose(self, cam: str, msg: PoseStamped) -> None:
        self._poses[cam] = msg
        self._update_cameras()

    def _update_cameras(self) -> None:
        if len(self.cameras) == len(self.camera_names):
            return
        for cam in self.camera_names:
            if cam in self._infos and cam in self._poses and cam not in self.cameras:
                try:
                    self.cameras[cam] = camera_from_msgs(cam, self._infos[cam], self._poses[cam])
                except InputError as exc:           # logged once per distinct error; the next message may do
                    if self._camera_errors.get(cam) != str(exc):
                        self._camera_errors[cam] = str(exc)
                        self.get_logger().error(f"{exc}; camera {cam} not used until a valid calibration arrives")
        self._process_pending()

    def _on_start(self, msg: String) -> None:
        if self.start is None and not self.auto_start:
            try:
                self.start = StartDescription.from_yaml_text(msg.data, START_TOPIC)
            except InputError as exc:
                self.get_logger().error(str(exc))
                return
            self._process_pending()

    def _on_body(self, msg: String) -> None:
        if not self._body_from_file:
            try:
                self.body = BodyDescription.from_yaml_text(msg.data, BODY_TOPIC)
            except InputError as exc:
                self.get_logger().error(f"{exc}; using the default body")
                self.body = BodyDescription.default()
            self._process_pending()

    def _on_features(self, cam: str, msg: ImageFeatures, info: dict | None = None) -> None:
        """``info``: rclpy's message info; its received_timestamp (system time, ns) is when the message arrived,
        before it waited in the subscription's queue."""
        stamp = stamp_to_ns(msg.header.stamp)
        try:
            item = features_from_msg(msg)
            camera = self.cameras.get(cam)
            if camera is not None and (item.image_width, item.image_height) != (camera.width, camera.height):
                raise InputError(f"features of a {item.image_width}x{item.image_height} image, but the "
                                 f"calibration of {cam} says {camera.width}x{camera.height}")
        except (InputError, ValueError) as exc:
            self.get_logger().error(f"/{cam}/features at {stamp} ns: {exc}; frame skipped")
            self._ack(stamp)
            return
        received = (info or {}).get("received_timestamp") or time.time_ns()
        self._arrivals[stamp] = min(self._arrivals.get(stamp, received), received)
        self._last_features[cam] = item
        self._take(*self.sync.add(cam, stamp, item))
        self._last_frame_time = time.monotonic()

    def _take(self, frames: list[Any], issues: list[Any]) -> None:
        """Log the synchroniser's issues; queue, filter and acknowledge (with its latest stamp) each frame, also one
        missing a camera (tracked with the others)."""
        for issue in issues:
            self.stats.sync_issues.append(issue.message)
            self.get_logger().warning(issue.message)
        now = time.time_ns()
        lags = [(now - self._arrivals.get(frame.last_stamp_ns, now)) * 1e-9 for frame in frames]
        waiting = set(self.sync.pending_stamps)
        self._arrivals = {s: t for s, t in self._arrivals.items() if s in waiting}
        for frame, lag in zip(frames, lags):
            if self.max_lag_s > 0 and lag > self.max_lag_s and self.tracker is not None:
                self._skip(frame.last_stamp_ns, lag)
                continue
            self.stats.largest_lag_s = max(self.stats.largest_lag_s, lag)
            self._pending.append(_Pending(frame.stamp_ns, self._frame_counter, frame.items))
            self._frame_counter += 1
            self.stats.frames_received += 1
            if len(self._first_stamps) < 2:
                self._first_stamps.append(frame.stamp_ns)
            self._process_pending()
            self._ack(frame.last_stamp_ns)

    def _skip(self, stamp_ns: int, lag: float) -> None:
        """Live and behind: leave out a frame that arrived ``lag`` s ago (acknowledged, counted, logged every 2 s);
        the filter steps over it by the stamps (``Tracker.push``)."""
        self._frame_counter += 1
        self.stats.frames_received += 1
        self.stats.frames_skipped += 1
        self._ack(stamp_ns)
        if time.monotonic() - self._skip_logged > 2.0:
            self._skip_logged = time.monotonic()
            self.get_logger().warning(
                f"behind the camera by {lag:.2f} s (max_lag_s {self.max_lag_s:g}): skipping frames to keep up, "
                f"{self.stats.frames_skipped} skipped so far; the filter steps over them by their stamps")

    def _filled(self, items: tuple[Any, ...]) -> tuple[Any, ...]:
        """A frame's features with features carrying no evidence for each camera it has none of
        (``vision.features.blank_features``, shaped as that camera's latest, else as another camera's)."""
        if all(item is not None for item in items):
            return items
        from awalker_tracker.vision.features import blank_features

        present = next(item for item in items if item is not None)
        filled = []
        for cam, item in zip(self.camera_names, items):
            if item is None:
                camera = self.cameras[cam]
                item = blank_features(self._last_features.get(cam, present), camera.width, camera.height)
            filled.append(item)
        return tuple(filled)

    def _ack(self, stamp_ns: int) -> None:
        self.ack_pub.publish(header(stamp_ns, self.world_frame))

    # -- filtering -------------------------------------------------------------------------
    def ready(self) -> bool:
        return (self.start is not None or self.auto_start) and len(self.cameras) == len(self.camera_names)

    def _dt(self) -> float | None:
        """Frame period (s): the frame_rate parameter, else the first two stamps; None until known."""
        if self.frame_rate > 0:
            return 1.0 / self.frame_rate
        if len(self._first_stamps) == 2:
            return (self._first_stamps[1] - self._first_stamps[0]) * 1e-9
        return None

    def _find_start(self, final: bool) -> bool:
        """Automatic start: feed the pending frames to the start finder until it finds the walking person;
        the frames of the window it found the walk over are tracked, earlier ones dropped (all already
        acknowledged). True once the start is known."""
        from awalker_tracker.inference.autostart import StartFinder

        dt = self._dt() or (1.0 / 30.0 if final else None)
        if dt is None:
            return False
        if self._finder is None:
            self._finder = StartFinder([self.cameras[c] for c in self.camera_names], dt, self.autostart_config)
            # the frames the finder saw, kept for as long as a start can reach back
            self._seen = deque(maxlen=self._finder.keep_frames)

        def started(found: Any) -> bool:
            # track from the start's frame, inside the window the walk was found over
            self._pending[:0] = [p for p in self._seen if p.frame_index >= found.frame]
            self.start, self.start_found_automatically = found, True
            hidden = self._finder.frames_feet_hidden
            self.get_logger().info(
                f"automatic start at frame {found.frame}: person at ({found.position[0]:.2f}, "
                f"{found.position[1]:.2f}) m, heading {np.degrees(found.heading):.0f} deg, "
                f"{found.speed:.2f} m/s, stance leg unknown (both sampled)"
                + (f"; their feet unseen (the blob ending above them) in {hidden} frames" if hidden else ""))
            self._write_start()
            return True

        while self._pending:
            item = self._pending[0]
            found = self._finder.push(item.frame_index, list(item.messages))
            if found is not None:
                return started(found)
            self._seen.append(self._pending.pop(0))
            if self._finder.frames_seen % 30 == 0:
                self.get_logger().info(f"automatic start: waiting for a walking person ({self._finder.status()})")
        if final and (found := self._finder.finish()) is not None:
            return started(found)
        if final and self.tracks_ended:
            self.get_logger().info(f"automatic start: no further walking person after track {self.tracks_ended} "
                                   f"({self._finder.status()})")
        elif final:
            self.get_logger().warning(f"automatic start: no walking person found ({self._finder.status()}); "
                                      "nothing tracked")
        return False

    def autostart_status(self) -> str | None:
        """What the automatic start has seen so far (``StartFinder.status``); None before it saw a frame."""
        return None if self._finder is None else self._finder.status()

    def _take_fitted_stance_leg(self) -> None:
        """A start naming no stance leg takes the fitted start's (``fitted_start``) when both start at the
        same frame; otherwise a warning, and both legs are sampled."""
        fitted, start = self.fitted_start, self.start
        if fitted is None or fitted.stance_leg is None or start.stance_leg is not None:
            return
        if fitted.frame != start.frame:
            self.get_logger().warning(
                f"fitted_start {self._fitted_start_path}: fitted at frame {fitted.frame}, but the start is at frame "
                f"{start.frame}; its stance leg is not used (both legs sampled)")
            return
        self.start = replace(start, stance_leg=fitted.stance_leg)
        self.get_logger().info(f"stance leg at frame {start.frame}: {LEG_NAMES[fitted.stance_leg]}, from the fitted "
                               f"start {self._fitted_start_path}")
        self._write_start()

    def _write_start(self) -> None:
        """The first track's start to ``start_output`` (the later tracks' starts are in the log)."""
        if self.start_output and self.start is not None and not self.tracks_ended:
            from pathlib import Path

            Path(self.start_output).write_text(self.start.to_yaml_text())

    def _make_tracker(self) -> bool:
        dt = self._dt()
        if dt is None:
            return False
        if self.body is None and self.estimate_body and self._finder is not None:
            height = self._finder.estimated_height()
            if height is not None:
                self.body = BodyDescription.from_seen_height(float(np.clip(height, 1.2, 2.1)),
                                                             len(self.camera_names))
                self.get_logger().info(f"body scaled to the person's height, {self.body.height:.2f} m (seen "
                                       f"{height:.2f} m): leg length {self.body.leg_length:.2f} m")
                if self.body_output:
                    from pathlib import Path

                    Path(self.body_output).write_text(self.body.to_yaml_text())
        if not self.tracks_ended:
            self._take_fitted_stance_leg()
        body = self.body or BodyDescription.default()
        cameras = [self.cameras[c] for c in self.camera_names]
        config = TrackerConfig(smc=self.smc_config, dt=dt, likelihood_scale=self.likelihood_scale,
                               recovery=self.recovery, view=self.view, leg_scale_spread=self.leg_scale_spread,
                               pelvis_ceiling=self.pelvis_ceiling,
                               pelvis_ceiling_min_cameras=self.pelvis_ceiling_min_cameras,
                               spread=AUTO_SPREAD if self.start_found_automatically else TrackerConfig.spread)
        model = TrackerModel(body, self.start, image_likelihood(body, cameras),
                             config, cameras=cameras)
        self.tracker = Tracker(model, track_id=self.tracks_ended + 1)
        count = particle_count_text(self.smc_config.num_particles, self.smc_config.min_particles)
        self.get_logger().info(f"track {self.tracker.track_id}: tracking with {count}, dt {dt * 1e3:.1f} ms, "
                               f"cameras {', '.join(self.camera_names)}, start frame {self.start.frame}")
        return True

    def _process_pending(self, final: bool = False) -> None:
        # at the end, a start finder that has seen every frame may still find the walk it has not finished fitting
        finding = final and self.start is None and self._finder is not None
        if not self.ready() or not (self._pending or finding):
            return
        for item in self._pending:
            item.messages = self._filled(item.messages)
        if self.start is None and not self._find_start(final):
            return
        if self.tracker is None and not self._make_tracker():
            if not final:
                return
            self.frame_rate = self.frame_rate or 30.0   # a single frame: any dt will do
            self._make_tracker()
        pending, self._pending = self._pending, []
        for k, item in enumerate(pending):
            if item.frame_index < self.start.frame:
                continue     # background-only frames before the person appears
            started = time.perf_counter()
            obs = ImageObservation(features=tuple(item.messages))
            summaries = self.tracker.push(item.frame_index, item.stamp_ns, obs)
            self.stats.seconds_in_filter += time.perf_counter() - started
            self.stats.frames_tracked += 1
            self._dirty = True
            self._publish(summaries)
            if self.tracker.ended is not None:
                self._end_track()
                # the frames after the end look for the next person
                self._pending = pending[k + 1:] + self._pending
                self._process_pending(final)
                return

    def _end_track(self) -> None:
        """The person left the view: keep the ended track, and find the next person (the automatic start, also
        after a hand start: it described the first person only)."""
        tracker, end = self.tracker, self.tracker.ended
        self.tracks_ended += 1
        if self.keep_summaries:     # (offline: poses.csv needs its MAP trajectory; its particles are not kept)
            self.ended_tracks.append(tracker.released())
        self.get_logger().info(
            f"frame {end.frame_index}: track {tracker.track_id} ended: the person {end.reason} (last in view at "
            f"frame {end.last_in_view_frame}); no more poses for them; waiting for a person to come into view")
        self.tracker, self.start, self.start_found_automatically = None, None, False
        self.auto_start, self._finder, self._dirty = True, None, False    # (a new finder keeps a new _seen)

    def all_tracks(self) -> list[Tracker]:
        """Every track of the run in order: the ended ones, then the current one (if any)."""
        return self.ended_tracks + ([self.tracker] if self.tracker is not None else [])

    def _publish(self, summaries: list[CoreSummary]) -> None:
        for s in summaries:
            self.posterior_pub.publish(summary_to_msg(s, self.world_frame))
            self.stats.summaries += 1
            self.stats.steps += len(s.steps)
            if s.reacquired:
                self.get_logger().info(f"frame {s.frame_index}: track lost, {s.reacquired} particles re-seeded "
                                       "at the person seen in the images")
            if s.legs_renamed:
                self.get_logger().info(f"frame {s.frame_index}: left and right renamed: the images favour the other "
                                       "naming of the legs")
            if s.person_still != self._person_still:
                self._person_still = s.person_still
                self.get_logger().info(
                    f"frame {s.frame_index}: the person stands still; the walkers are held where they stand (the "
                    "walker model only walks) until the person walks on" if s.person_still
                    else f"frame {s.frame_index}: the person walks on")
            if self.keep_summaries:
                self.summaries.append(s)

    def flush(self) -> int:
        """Complete all frames still waiting for a camera or for look-ahead data; returns how many were published."""
        self._take(*self.sync.flush())
        self._process_pending(final=True)
        if self.tracker is None or not self._dirty:
            return 0
        summaries = self.tracker.finish()
        self._dirty = False
        self._publish(summaries)
        return len(summaries)

    def _on_timer(self) -> None:
        now = time.time_ns()
        waiting = self.sync.pending_stamps
        if waiting and (now - self._arrivals.get(waiting[0], now)) * 1e-9 > self.sync_timeout_s:
            self._take(*self.sync.expire(f"waited {self.sync_timeout_s:.1f} s"))
        if self._dirty and time.monotonic() - self._last_frame_time > self.idle_flush_s:
            self.flush()


def main(args: list[str] | None = None) -> int:
    """Console script ``awalker_tracker_node``; exit status 2 on bad parameters."""
    return run_node("awalker_tracker_node", TrackerNode, args, parameters=PARAMETERS,
                    summary="Per-camera image features -> the physics-based particle filter -> posterior "
                            "summaries on /awalker/posterior.")

