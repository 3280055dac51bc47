"""Starting without a start description: find the walking person in the first frames.

``StartFinder`` is fed each frame's image features. Per frame it detects the person
(``vision.detection``: the largest foreground blob, placed on the ground through the calibrated
cameras; with several, the other cameras' blobs where its feet put the person) and keeps the
frames where the person is wholly in view of some camera. Once the detections over ``window_s``
(at least ``min_fraction`` of its frames) form a ground track moving at ``min_speed_m_s`` or
faster, the start is the central frame of that window's detections, where the straight-line fit of
the track's positions is most precise (the caller keeps the window's frames and tracks from there:
the track begins about ``window_s`` / 2 before the walk was found), that fit's position at it, its
direction (heading) and speed (clamped to ``speed_range_m_s``, the gaits the tracker knows); step
length: the usual one at that speed; stance leg unknown (both sampled, at any phase). Before that it
answers None: a person standing still, half out of view, or nobody, does not start the tracker. The detections' heights (top of the blob over the ground point) give the
person's height (``estimated_height``), from which a body can be scaled when nobody measured one.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awalker_tracker.inference.tracker import InitialSpread, StartDescription
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import GroundTrack, PersonDetection, detect_person, wholly_in_view


# Initial particles of an automatic start: wider than around a hand-written start (one camera places the
# person to ~0.1 m in depth and the heading to ~10-15 degrees), at any phase of either leg.
AUTO_SPREAD = InitialSpread(position_m=0.15, heading_rad=0.2, speed_fraction=0.2, step_length_fraction=0.1,
                            joint_rad=0.05, random_phase=True)


@dataclass(frozen=True)
class AutoStartConfig:
    """When the detections are a walking person (times s, speeds m/s)."""

    window_s: float = 0.7           # one camera: 0.5 s gave 13 degrees of heading error, 0.7 s 10, 1.0 s 4
    min_fraction: float = 0.8
    min_speed_m_s: float = 0.4
    speed_range_m_s: tuple[float, float] = (0.6, 1.9)

    def __post_init__(self) -> None:
        if not (self.window_s > 0 and 0 < self.min_fraction <= 1 and self.min_speed_m_s >= 0
                and 0 < self.speed_range_m_s[0] < self.speed_range_m_s[1]):
            raise ValueError(f"AutoStartConfig: invalid settings {self}")


class StartFinder:
    """Frame by frame, the start description of the walking person once it is clear (module docstring)."""

    def __init__(self, cameras: list[Camera], dt: float, config: AutoStartConfig = AutoStartConfig()) -> None:
        self.cameras = list(cameras)
        self.config = config
        self.track = GroundTrack(dt)
        self.frames_seen = 0
        self.frames_detected = 0
        self.last_detection: PersonDetection | None = None
        self.heights: list[float] = []

    def estimated_height(self) -> float | None:
        """Median height (m) of the person over the frames seen wholly so far (None before any)."""
        return float(np.median(self.heights)) if self.heights else None

    def push(self, frame: int, features: list[Any]) -> StartDescription | None:
        """The start description if the person is found walking by ``frame``, else None. Its frame is the
        central frame of the window the walk was found over (about ``window_s`` / 2 before ``frame``)."""
        self.frames_seen += 1
        # not gated on the last sighting: that follows the ghost a median background leaves where the
        # person walked in its first frames, once it splits off the person's blob
        detection = detect_person(list(features), self.cameras)
        whole = detection is not None and wholly_in_view(detection, self.cameras)
        self.track.add(frame, detection.position if whole else None)
        if not whole:
            return None
        self.frames_detected += 1
        self.last_detection = detection
        if np.isfinite(detection.height):
            self.heights.append(float(detection.height))
        cfg = self.config
        velocity = self.track.velocity(frame, cfg.window_s, cfg.min_fraction)
        if velocity is None or np.linalg.norm(velocity) < cfg.min_speed_m_s:
            return None
        central = self.track.central_frame(frame, cfg.window_s)
        position = self.track.fitted_position(frame, cfg.window_s, at=central)
        speed = float(np.clip(np.linalg.norm(velocity), *cfg.speed_range_m_s))
        return StartDescription(frame=int(central), position=(float(position[0]), float(position[1])),
                                heading=float(np.arctan2(velocity[1], velocity[0])), speed=speed,
                                step_length=None, stance_leg=None)

    def status(self) -> str:
        """What has been seen so far, for a log line while waiting."""
        if self.frames_detected == 0:
            return f"no person seen in {self.frames_seen} frames"
        return (f"person wholly in view in {self.frames_detected} of {self.frames_seen} frames, "
                f"not yet walking steadily for {self.config.window_s:g} s")
