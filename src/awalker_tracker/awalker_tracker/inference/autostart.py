"""Starting without a start description: find the walking person in the first frames.

``StartFinder`` is fed each frame's image features. Per frame it detects the person
(``vision.detection``: the largest foreground blob, placed on the ground through the calibrated
cameras; with several, the other cameras' blobs where its feet put the person; once someone was seen,
within ``gate_s``, each camera's blob nearest to them, so that with two people in view the first one
seen is followed; ``follow_near`` chooses another: until someone is seen, only a person within
``follow_radius_m`` of that ground point counts) and keeps the frames where the person is wholly in view of some camera. Once the detections over ``window_s``
(at least ``min_fraction`` of its frames) form a ground track moving at ``min_speed_m_s`` or
faster, the start is the central frame of that window's detections (the caller keeps the window's
frames and tracks from there: the track begins about ``window_s`` / 2 before the walk was found).
Its position, heading and speed (clamped to ``speed_range_m_s``, the gaits the tracker knows) come
from a straight-line fit of the track over ``fit_window_s`` from the window's first frame: the
finder waits that much longer before answering (one camera places the feet in steps of a map row,
0.2 m in depth at 5 m, so a 0.7 s track's direction is 10-20 degrees off; over 1.3 s, 3-6), or
answers with what it has at ``finish`` (the sequence ended). Step length: the usual one at that
speed; stance leg unknown (both sampled, at any phase). Before that it
answers None: a person standing still, half out of view, or nobody, does not start the tracker. The detections' heights (top of the blob over the ground point) give the
person's height (``estimated_height``), from which a body can be scaled when nobody measured one.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awalker_tracker.inference.filter_model import InitialSpread, StartDescription
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import GroundTrack, PersonDetection, detect_person, wholly_in_view


# Initial particles of an automatic start: wider than around a hand-written start (one camera places the
# person to ~0.1 m in depth and the heading to ~10-15 degrees), at any phase of either leg.
AUTO_SPREAD = InitialSpread(position_m=0.15, heading_rad=0.2, speed_fraction=0.2, step_length_fraction=0.1,
                            joint_rad=0.05, random_phase=True)


@dataclass(frozen=True)
class AutoStartConfig:
    """When the detections are a walking person (times s, speeds m/s)."""

    window_s: float = 0.7           # walking steadily over this long starts the tracker
    fit_window_s: float = 1.3       # position, heading and speed fitted over this long from the window's start
    gate_s: float = 0.5             # detections follow the person seen within this long (several people)
    gate_m: float = 0.5             # ... and within this distance of where they would be now
    min_fraction: float = 0.8
    min_speed_m_s: float = 0.4
    speed_range_m_s: tuple[float, float] = (0.6, 1.9)
    follow_near: tuple[float, float] | None = None   # world ground point (m): follow the person first seen near it
    follow_radius_m: float = 1.5                     # ... within this distance (several people in view)

    def __post_init__(self) -> None:
        if not (0 < self.window_s <= self.fit_window_s and 0 < self.min_fraction <= 1 and self.gate_s >= 0
                and self.gate_m > 0 and self.min_speed_m_s >= 0 and 0 < self.speed_range_m_s[0] < self.speed_range_m_s[1]
                and self.follow_radius_m > 0):
            raise ValueError(f"AutoStartConfig: invalid settings {self}")
        if self.follow_near is not None and not (len(self.follow_near) == 2 and np.all(np.isfinite(self.follow_near))):
            raise ValueError(f"AutoStartConfig: follow_near must be a finite ground point (x, y) in m, got "
                             f"{self.follow_near!r}")


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
        self._found: tuple[int, int] | None = None     # (start frame, first frame of its window) once walking
        self._last_seen: tuple[int, np.ndarray] | None = None   # (frame, ground position) of the last sighting
        self._last_frame = -1

    @property
    def keep_frames(self) -> int:
        """How many frames before the current one a start can reach back to (the caller keeps them)."""
        return int(np.ceil(self.config.fit_window_s / self.track.dt)) + 2

    def estimated_height(self) -> float | None:
        """Median height (m) of the person over the frames seen wholly so far (None before any)."""
        return float(np.median(self.heights)) if self.heights else None

    def push(self, frame: int, features: list[Any]) -> StartDescription | None:
        """The start description once the person was found walking and ``fit_window_s`` of track is in,
        else None. Its frame is the central frame of the window the walk was found over."""
        self.frames_seen += 1
        self._last_frame = frame
        # the person seen last (within gate_s), where they would be now (carried on at their velocity over
        # the window, once half its frames have a position; else anywhere a fast walk reaches): each
        # camera's blob nearest to there, and a detection farther than gate_m from it is someone else (or
        # two people's blobs merged)
        cfg = self.config
        predicted, reach = None, cfg.gate_m
        since = None if self._last_seen is None else (frame - self._last_seen[0]) * self.track.dt
        if since is not None and since <= cfg.gate_s:
            velocity = self.track.velocity(self._last_seen[0], cfg.window_s, min_fraction=0.5)
            predicted = self._last_seen[1] + (0.0 if velocity is None else since * velocity)
            reach = cfg.gate_m + (cfg.speed_range_m_s[1] * since if velocity is None else 0.0)
        elif self._last_seen is None and cfg.follow_near is not None:
            predicted, reach = np.asarray(cfg.follow_near, float), cfg.follow_radius_m
        detection = detect_person(list(features), self.cameras,
                                  near=None if predicted is None else np.append(predicted, 0.9))
        whole = detection is not None and wholly_in_view(detection, self.cameras) and (
            predicted is None or np.linalg.norm(detection.position - predicted) <= reach)
        self.track.add(frame, detection.position if whole else None)
        if whole:
            self._last_seen = (frame, detection.position)
        if self._found is not None:
            if frame - self._found[1] >= self.track.span(cfg.fit_window_s):
                return self.finish()
            return None
        if not whole:
            return None
        self.frames_detected += 1
        self.last_detection = detection
        if np.isfinite(detection.height):
            self.heights.append(float(detection.height))
        velocity = self.track.velocity(frame, cfg.window_s, cfg.min_fraction)
        if velocity is None or np.linalg.norm(velocity) < cfg.min_speed_m_s:
            return None
        self._found = (int(self.track.central_frame(frame, cfg.window_s)), frame - self.track.span(cfg.window_s))
        return None

    def finish(self) -> StartDescription | None:
        """The start of the person found walking, fitted over the track seen so far (``push`` calls it
        once ``fit_window_s`` is in; call it when the sequence ends before that), else None."""
        if self._found is None:
            return None
        central, first = self._found
        window_s = (self._last_frame - first) * self.track.dt
        velocity = self.track.velocity(self._last_frame, window_s, min_fraction=0.0)
        position = self.track.fitted_position(self._last_frame, window_s, at=central)
        speed = float(np.clip(np.linalg.norm(velocity), *self.config.speed_range_m_s))
        return StartDescription(frame=central, position=(float(position[0]), float(position[1])),
                                heading=float(np.arctan2(velocity[1], velocity[0])), speed=speed,
                                step_length=None, stance_leg=None)

    def status(self) -> str:
        """What has been seen so far, for a log line while waiting."""
        if self.frames_detected == 0:
            near = ("" if self.config.follow_near is None else
                    f" within {self.config.follow_radius_m:g} m of ({self.config.follow_near[0]:g}, "
                    f"{self.config.follow_near[1]:g}) m")
            return f"no person seen{near} in {self.frames_seen} frames"
        if self._found is not None:
            return (f"person walking since frame {self._found[0]}, fitting the track over "
                    f"{self.config.fit_window_s:g} s")
        return (f"person wholly in view in {self.frames_detected} of {self.frames_seen} frames, "
                f"not yet walking steadily for {self.config.window_s:g} s")
