"""Starting without a start description: find the walking person in the first frames.

``StartFinder`` is fed each frame's image features. Per frame it follows everyone it has seen
(``vision.detection``: each person-sized foreground blob, placed on the ground through the calibrated
cameras; with several cameras, the other cameras' blobs where its feet put the person): each one
followed takes, within ``gate_s`` of their last sighting, each camera's blob nearest to where they
would be now (the one seen first chooses first; a detection farther than ``gate_m`` is someone else, or
two people's blobs merged), and every blob nobody took is someone new (up to ``max_candidates``;
``follow_near`` chooses one: the person nearest that ground point, within ``follow_radius_m``, and only
them). Following several at once is
what starts on a person who stood still before walking off: with no empty frames the background is
learned from the walk itself, the standing person becomes part of it, and where they stood a "ghost"
blob stays behind them, motionless; a finder following only the first one seen followed the ghost
and never started (real walks hands off, one camera: 69_01 seed 0). Only frames where the person is
wholly in view of some camera count, and with one camera only where one map row at the feet spans at most
``max_row_depth_m`` of depth (``PersonDetection.row_depth_m``): from far and low (9.4 m at 1.6 m high, 0.9 m
per row on a tuning walk) the feet rows were metres off, and a track restarted there began 6.8 m from the
person; the finder then says the camera is too far or too low rather than start. Once someone's detections over ``window_s``
(at least ``min_fraction`` of its frames) form a ground track moving at ``min_speed_m_s`` or
faster (the first seen of those who do, then the larger blob; frames where their blob ends above the feet,
``feet_hidden_height_ratio``, count as seen but not placed), the start is the central frame of that window's
detections (the caller keeps the window's frames and tracks from there: the track begins about ``window_s`` / 2
before the walk was found).
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

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from awalker_tracker.inference.filter_model import InitialSpread, StartDescription
from awalker_tracker.inference.recovery import RecoveryConfig
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import (
    GroundTrack, PersonBlob, PersonDetection, ground_point, locate_person, on_blob, person_blobs, wholly_in_view)


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
    max_candidates: int = 4         # people (or ghosts) followed at once while none walks steadily
    max_row_depth_m: float = 0.5    # one camera: a feet row spanning more depth than this per map row does not count
    # A feet-row sighting whose blob stands taller than this times the person's median height so far (after
    # feet_hidden_after sightings) has lost its legs to the floor (bare legs, shorts or a skirt near the floor's
    # colour: the blob ends at the hem and the feet row puts them metres farther): the person was seen there,
    # not placed (``GroundTrack.add(seen=True)``). The recovery's feet rows stop counting at the same ratio.
    feet_hidden_height_ratio: float = RecoveryConfig.feet_row_height_ratio[1]
    feet_hidden_after: int = 5

    def __post_init__(self) -> None:
        if not (0 < self.window_s <= self.fit_window_s and 0 < self.min_fraction <= 1 and self.gate_s >= 0
                and self.gate_m > 0 and self.min_speed_m_s >= 0 and 0 < self.speed_range_m_s[0] < self.speed_range_m_s[1]
                and self.follow_radius_m > 0 and self.max_candidates >= 1 and self.max_row_depth_m > 0
                and self.feet_hidden_height_ratio > 1 and self.feet_hidden_after >= 1):
            raise ValueError(f"AutoStartConfig: invalid settings {self}")
        if self.follow_near is not None and not (len(self.follow_near) == 2 and np.all(np.isfinite(self.follow_near))):
            raise ValueError(f"AutoStartConfig: follow_near must be a finite ground point (x, y) in m, got "
                             f"{self.follow_near!r}")


@dataclass
class _Candidate:
    """Someone the finder follows: a person, or the ghost a person leaves where they stood in a background
    learned from the walk itself (ground positions per frame, the last sighting, heights seen)."""

    track: GroundTrack
    first_frame: int
    area_px: float                       # the first blob's (a tie between two found walking at once: the larger)
    last_seen: tuple[int, np.ndarray]
    heights: list[float]


class StartFinder:
    """Frame by frame, the start description of the walking person once it is clear (module docstring)."""

    def __init__(self, cameras: list[Camera], dt: float, config: AutoStartConfig = AutoStartConfig()) -> None:
        self.cameras = list(cameras)
        self._by_name = {c.name: c for c in self.cameras}
        self.config = config
        self.dt = float(dt)
        self.frames_seen = 0
        self.frames_detected = 0
        self.frames_feet_hidden = 0     # frames the person was seen in with their feet unseen (``_feet_hidden``)
        self._candidates: list[_Candidate] = []
        self._coarse: deque[float] = deque(maxlen=300)   # row depths (m) of recent detections too coarse to count
        self._found: tuple[int, int, _Candidate] | None = None   # (start frame, its window's first frame, who)
        self._last_frame = -1

    @property
    def keep_frames(self) -> int:
        """How many frames before the current one a start can reach back to (the caller keeps them)."""
        return int(np.ceil(self.config.fit_window_s / self.dt)) + 2

    def estimated_height(self) -> float | None:
        """Median height (m) of the person found walking (before that: of the one seen wholly in the most
        frames) over the frames seen wholly so far (None before any)."""
        if self._found is not None:
            heights = self._found[2].heights
        else:
            heights = max((c.heights for c in self._candidates), key=len, default=[])
        return float(np.median(heights)) if heights else None

    def _predicted(self, candidate: _Candidate, frame: int) -> tuple[np.ndarray, float]:
        """Where ``candidate`` would be at ``frame`` (carried on at their velocity over the window, once half
        its frames have a position) and how far from there a detection may lie (m; with no velocity, as far
        as a fast walk reaches since the last sighting)."""
        cfg = self.config
        last, position = candidate.last_seen
        since = (frame - last) * self.dt
        velocity = candidate.track.velocity(last, cfg.window_s, min_fraction=0.5)
        if velocity is None:
            return position, cfg.gate_m + cfg.speed_range_m_s[1] * since
        return position + since * velocity, cfg.gate_m

    def _feet_hidden(self, candidate: _Candidate, detection: PersonDetection, pelvis: np.ndarray) -> bool:
        """Whether ``detection`` (wholly in view, placed by a feet row, its blob over ``pelvis``, the world point
        (3,) where ``candidate``'s pelvis would be now) stands taller than ``feet_hidden_height_ratio`` times the
        candidate's median height: its blob ends above the feet."""
        cfg = self.config
        if (detection.triangulated or not np.isfinite(detection.height)
                or len(candidate.heights) < cfg.feet_hidden_after or not wholly_in_view(detection, self.cameras)):
            return False
        over = any(on_blob(self._by_name[b.camera], pelvis, b, margin=0.0) for b in detection.blobs)
        return over and detection.height > cfg.feet_hidden_height_ratio * float(np.median(candidate.heights))

    def push(self, frame: int, features: list[Any]) -> StartDescription | None:
        """The start description once the person was found walking and ``fit_window_s`` of track is in,
        else None. Its frame is the central frame of the window the walk was found over."""
        self.frames_seen += 1
        self._last_frame = frame
        cfg = self.config
        seen = [person_blobs(f, c.name) for f, c in zip(features, self.cameras)]
        taken: set[PersonBlob] = set()

        def placed(detection: PersonDetection | None) -> bool:
            """Wholly in view, and (one camera's feet row) placed to within ``max_row_depth_m`` per map row."""
            if detection is None or not wholly_in_view(detection, self.cameras):
                return False
            if detection.row_depth_m > cfg.max_row_depth_m:
                self._coarse.append(detection.row_depth_m)
                return False
            return True
        # everyone followed (within gate_s of their last sighting): each camera's blob nearest to where they
        # would be now, a detection farther than the reach someone else (or two people's blobs merged); the
        # one seen first chooses first
        followed = [self._found[2]] if self._found is not None else self._candidates
        hidden_now = False
        for candidate in followed:
            predicted, reach = self._predicted(candidate, frame)
            pelvis = np.append(predicted, 0.9)
            detection = locate_person(seen, self.cameras, near=pelvis)
            free = detection is not None and not taken.intersection(detection.blobs)
            hidden = free and self._feet_hidden(candidate, detection, pelvis)
            whole = (not hidden and placed(detection) and np.linalg.norm(detection.position - predicted) <= reach
                     and free)
            candidate.track.add(frame, detection.position if whole else None, seen=hidden)
            hidden_now |= hidden
            if hidden or whole:
                taken.update(detection.blobs)
            if whole:
                candidate.last_seen = (frame, detection.position)
                if np.isfinite(detection.height):
                    candidate.heights.append(float(detection.height))
        self.frames_feet_hidden += hidden_now
        if self._found is not None:
            if frame - self._found[1] >= self._found[2].track.span(cfg.fit_window_s):
                return self.finish()
            return None
        self._candidates = [c for c in self._candidates if (frame - c.last_seen[0]) * self.dt <= cfg.gate_s]
        # newcomers: every person-sized blob nobody followed took; with follow_near, only the one nearest that
        # point (within follow_radius_m) while nobody is followed yet
        newcomers = []
        for blobs, camera in zip(seen, self.cameras):
            for blob in blobs:
                if blob in taken or len(self._candidates) + len(newcomers) >= cfg.max_candidates:
                    continue
                ground = ground_point(camera, blob.feet_uv)
                detection = None if ground is None else locate_person(seen, self.cameras, near=np.append(ground, 0.9))
                if not placed(detection) or taken.intersection(detection.blobs):
                    continue
                taken.update(detection.blobs)
                newcomers.append((blob, detection))
        if cfg.follow_near is not None:
            gap = lambda d: float(np.linalg.norm(d.position - np.asarray(cfg.follow_near)))  # noqa: E731
            near = [(b, d) for b, d in newcomers if gap(d) <= cfg.follow_radius_m]
            newcomers = [] if self._candidates or not near else [min(near, key=lambda bd: gap(bd[1]))]
        for blob, detection in newcomers:
            track = GroundTrack(self.dt)
            track.add(frame, detection.position)
            heights = [float(detection.height)] if np.isfinite(detection.height) else []
            self._candidates.append(_Candidate(track, frame, blob.area_px, (frame, detection.position), heights))
        if any(c.last_seen[0] == frame for c in self._candidates):
            self.frames_detected += 1
        # the first seen (then the larger) of those walking steadily over window_s
        for candidate in sorted(self._candidates, key=lambda c: (c.first_frame, -c.area_px)):
            velocity = candidate.track.velocity(frame, cfg.window_s, cfg.min_fraction)
            if velocity is not None and np.linalg.norm(velocity) >= cfg.min_speed_m_s:
                self._found = (int(candidate.track.central_frame(frame, cfg.window_s)),
                               frame - candidate.track.span(cfg.window_s), candidate)
                break
        return None

    def finish(self) -> StartDescription | None:
        """The start of the person found walking, fitted over the track seen so far (``push`` calls it
        once ``fit_window_s`` is in; call it when the sequence ends before that), else None."""
        if self._found is None:
            return None
        central, first, candidate = self._found
        window_s = (self._last_frame - first) * self.dt
        velocity = candidate.track.velocity(self._last_frame, window_s, min_fraction=0.0)
        position = candidate.track.fitted_position(self._last_frame, window_s, at=central)
        speed = float(np.clip(np.linalg.norm(velocity), *self.config.speed_range_m_s))
        return StartDescription(frame=central, position=(float(position[0]), float(position[1])),
                                heading=float(np.arctan2(velocity[1], velocity[0])), speed=speed,
                                step_length=None, stance_leg=None)

    def status(self) -> str:
        """What has been seen so far, for a log line while waiting."""
        if self.frames_detected == 0 and self._coarse:
            return (f"no person placed in {self.frames_seen} frames: one image row at their feet spans a median "
                    f"{np.median(self._coarse):.2f} m of depth (more than {self.config.max_row_depth_m:g} m: the "
                    "camera is too far or too low to place them from the feet)")
        if self.frames_detected == 0:
            near = ("" if self.config.follow_near is None else
                    f" within {self.config.follow_radius_m:g} m of ({self.config.follow_near[0]:g}, "
                    f"{self.config.follow_near[1]:g}) m")
            return f"no person seen{near} in {self.frames_seen} frames"
        if self._found is not None:
            return (f"person walking since frame {self._found[0]}, fitting the track over "
                    f"{self.config.fit_window_s:g} s")
        hidden = f" (and in {self.frames_feet_hidden} more with the feet unseen)" if self.frames_feet_hidden else ""
        return (f"person wholly in view in {self.frames_detected} of {self.frames_seen} frames{hidden}, "
                f"not yet walking steadily for {self.config.window_s:g} s")
