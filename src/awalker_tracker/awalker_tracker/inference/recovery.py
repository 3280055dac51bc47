"""Recovery of a lost or fallen track: settings, the lost-track monitor and row replacement.

Two failure modes of the physics-based filter are not repaired by the likelihood alone:

- **Falls.** A walker that falls (hip on the ground, a leg past horizontal, no heel strike for 2 s)
  never gets up: without recovery it keeps a large log-likelihood penalty and, when every particle
  has fallen, the posterior is a body lying on the floor. With ``reseed_fallen`` each particle whose
  walker falls is replaced, in the frame it falls, by a walker on the cyclic gait of its recent
  speed (clamped to the gait table), caught where it fell: its pelvis kept, the leg that swung just
  struck in front, with its heading.
- **Lost tracks.** The person followed is, in each camera, the foreground blob nearest to where the
  particles' weighted-mean pelvis projects (``vision.detection``; a second person elsewhere in view
  is not mixed in). The track is lost when, for ``lost_after_s``, that pelvis projects outside every
  person-sized blob in every camera that sees the person; or, where cameras at different angles place
  the person on the ground (``PersonDetection.triangulated``), lies more than ``lost_distance_m`` from
  that place over the ground; or, with one camera, lies a median ``lost_distance_one_camera_m`` (0.6 m)
  over ``track_window_s`` from where the blob's feet row places the person, or ``lost_rows_one_camera``
  (2) map rows of that feet row's depth if farther (``PersonDetection.row_depth_m``: one row spans about
  (D^2 + h^2) / h x row / focal length over the ground, 0.05-0.15 m from 3-5 m at 1.5-2 m high, but ~1 m
  from 9.6 m at 0.8 m high, where a fixed 0.6 m fired on feet-row noise, moved a hand-started track
  that was 0.1 m from the person onto a feet row 0.8 m too far and lost it: real walks 07_01-uturn and
  91_10, seed 0, 868 and 1510 mm). One camera's feet row is
  0.06-0.25 m too near on the real walks (``benchmarks/bench_realwalks.py``, median per walk) and
  scattered by ~0.1 m, too coarse to hold the depth, but a body drifting along the line of sight stays
  on the person's image and the blob test alone never fired (8 of 60 one-camera runs ended 0.5-1.6 m
  off). A feet row counts only where the blob stands as tall as the body (``feet_row_height_ratio``,
  0.85-1.10 of its height; a walking person's blob is 0.91-0.96 on the real walks): legs hidden behind
  something, or a blob that lost the head or merged with a shadow, misplace it by metres. Nor where it
  jumps: a feet row counts only within ``reach_m`` (or ``reach_rows`` map rows of its depth, where farther: a
  far, low camera's feet row moves in steps of a whole row) + ``reach_m_s`` x (time since the last one counted)
  of where the counted ones put the person now (the last of them, moved on at their velocity over
  ``track_window_s``), unless none has counted for ``reach_reset_s``, or (one camera, ``reach_agree_s`` > 0) this
  one and the feet rows left out over the last ``reach_agree_s``, one every frame, all lie within that reach of
  each other and of the particles' pelvis: a far, low camera's feet row that stepped a row or two from where the
  counted ones were and stayed there. Legs hidden behind a box put the
  blob's lowest row on the box's top edge, metres behind the person, and with the camera near head
  height the blob still looks as tall as the body (a box in front of a whole 40-frame walk, ``synth
  --occluder 1.2``: 3.4 m behind, ratio under 1.10); people do not jump, so those rows are not counted (for up to ``reach_reset_s``: legs
  hidden longer, or a track that started on hidden legs, count again). Where the camera has an occlusion
  mask (something known to stand in front of the person), a blob whose lowest row lies on it does not
  count either (``detection.ends_on_occlusion``): where the legs are hidden from the first frame (that
  render), the feet rows are wrong from the start and the reach test cannot tell. When lost, a
  fraction of the particles (the lowest weights) are re-seeded around the detected ground position,
  with the heading and speed of the detections' recent ground track (when it moves), then the image
  likelihood decides. At most once per ``cooldown_s``.
- **One camera's depth (on: ``depth_band_m`` 0.15; ``awalker track --depth-band 0`` turns it off).** A
  single camera sees a step toward or away from it hardly at all, so the depth wanders like a random
  walk (the real walks' pelvis error along the view over the last second of a run: median 0.18 m, 90th
  percentile 0.56 m). With ``depth_band_m`` > 0, where this frame's feet row counts (above), from
  ``depth_band_delay_s`` after the first frame tracked on (``LostTrackMonitor.depth_band``), walkers whose pelvis
  lies more than ``depth_band_m`` from it over the ground lose up to 0.5 (excess / ``depth_band_sigma_m``)^2
  nats (``TrackerModel.depth_band_penalty``; the band is ``depth_band_rows`` (1) map rows of the feet
  row's depth wide where that is wider), levelling off at ~-log(``depth_band_outlier``) because a
  feet row can be wrong (feet hidden behind something put it metres away while the blob still looks as
  tall as the body). The feet row is a map row (4 px at 320x240: ~0.27 m of depth at 5 m) and biased by
  the look of the feet (~0.2 m too near on the dressed renders, their contact shadow; on our own body's
  renders it jumps a row or two too far in some frames, where the feet's ratio falls under the blob's
  threshold), so it only holds the depth within a band, and not over the first half second, when the
  start is better than any one feet row (a hand start is right to 5 cm; the automatic start is made from
  the feet rows themselves). Measured in docs/tracking.md (Recovery, *One camera's depth band*).
- **One camera's heading (off: ``heading_band_rad`` 0).** Seen from one side a walker facing 40-110 degrees
  off still covers the person's silhouette, and slow walkers' headings drifted that far while the feet rows went
  straight on. With ``heading_band_rad`` > 0, where this frame's feet row counts and the counted feet rows moved
  at ``moving_m_s`` or faster over ``heading_band_window_s`` and its last half, in directions within
  ``heading_band_turning_rad`` of each other (not turning), walkers heading farther than the band's half width
  from that direction lose up to 0.5 (excess / ``heading_band_sigma_rad``)^2 nats, levelling off as the depth
  band's does (``TrackerModel.heading_band_penalty``). The half width is ``heading_band_rad`` plus the angle
  between the two directions plus the angle a map row of the feet row's depth subtends over the distance moved:
  a far, low camera places the feet in steps of a row along its view. Measured in docs/tracking.md (Recovery,
  *One camera's heading band*).
- **A person who stops.** The walker only walks (the paper's model has no standing still): with
  ``hold_still``, while the detections' ground track moves slower than ``still_m_s`` over
  ``still_window_s`` (and until it moves faster than ``moving_m_s`` again), each frame's particles
  are the previous frame's, held where they stand with speed 0 (``HELD``), and the summaries say the
  person stands still; when the person walks on, the walkers go on from where they were held.

Both are proposals the prior does not make, and their weights are not corrected for it: recovery
trades the filter's exactness for not staying lost. The summaries count the re-seeded particles.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Any

import numpy as np

from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import (
    GroundTrack, PersonBlob, PersonDetection, ends_on_occlusion, locate_person, on_blob, person_blobs, wholly_in_view)

NOT_RESEEDED, RESEEDED_FALLEN, REACQUIRED, HELD = 0, 1, 2, 3


@dataclass(frozen=True)
class RecoveryConfig:
    """When and how the tracker re-seeds particles (see the module docstring)."""

    reseed_fallen: bool = True
    reacquire: bool = True
    lost_after_s: float = 0.2          # off the person this long before re-acquiring
    cooldown_s: float = 0.5            # at most one re-acquisition per this time
    reacquire_fraction: float = 0.5    # share of the particles (lowest weights) re-seeded at the person
    position_spread_m: float = 0.15    # re-seeded pelvis ground positions around the detection
    heading_spread_rad: float = 0.25
    box_margin: float = 0.25           # the blob box is widened by this fraction of its size on each side
    lost_distance_m: float = 0.4       # triangulated detections: the pelvis this far off over the ground is lost
    lost_distance_one_camera_m: float = 0.6  # feet-row detections (one camera): the median over track_window_s
    lost_rows_one_camera: float = 2.0  # ... or this many map rows of the feet row's depth (row_depth_m), if farther
    feet_row_height_ratio: tuple[float, float] = (0.85, 1.10)  # ... of frames whose blob is this tall (x body height)
    reach_m: float = 0.5               # ... and whose feet row lies within this of where the counted ones put the
    reach_rows: float = 1.5            # ... person (or this many map rows of the feet row's depth, if farther),
    reach_m_s: float = 0.5             # ... now, plus this per second since the last counted one,
    reach_reset_s: float = 2.0         # ... unless none counted for this long (module docstring),
    reach_agree_s: float = 0.3         # ... or the feet rows left out for this long lie within that reach of
    #                                    this one (0: off; module docstring)
    track_window_s: float = 0.5        # detections over this time give the person's ground velocity
    moving_m_s: float = 0.3            # slower ground tracks give no heading (and do not end a stop)
    hold_still: bool = True            # hold the walkers while the person stands still
    still_m_s: float = 0.15            # a ground track slower than this over still_window_s: standing still
    still_window_s: float = 0.3
    depth_band_m: float = 0.15         # one camera: the pelvis this far from the feet-row position is free ...
    depth_band_rows: float = 1.0       # ... or this many map rows of its depth (row_depth_m), if farther
    depth_band_sigma_m: float = 0.1    # ... beyond it each frame costs 0.5 (excess / sigma)^2 nats; band 0: off
    depth_band_outlier: float = 0.05   # ... up to ~-log(this): a feet row may be wrong (feet hidden)
    depth_band_delay_s: float = 0.5    # ... from this long (s) after the first frame tracked: the start holds before
    # one camera's heading band (module docstring; 0: off, the default: at 0.6 within the runs' spread on the
    # tuning subjects, docs/tracking.md, *One camera's heading band*): walkers heading this far (rad) from where the
    # feet rows go are free ...
    heading_band_rad: float = 0.0
    heading_band_sigma_rad: float = 0.2   # ... beyond it each frame costs 0.5 (excess / sigma)^2 nats, up to
    #                                       ~-log(depth_band_outlier)
    heading_band_window_s: float = 1.0    # ... the track's direction over this time, where it moves at moving_m_s
    heading_band_turning_rad: float = 0.35   # ... and over the window's last half within this of it (not turning)

    def __post_init__(self) -> None:
        low, high = self.feet_row_height_ratio
        if not 0.0 < low < high:
            raise ValueError(f"RecoveryConfig.feet_row_height_ratio must be (low, high) with 0 < low < high, "
                             f"got {self.feet_row_height_ratio}")
        if not 0.0 < self.reacquire_fraction <= 1.0:
            raise ValueError(f"RecoveryConfig.reacquire_fraction must lie in (0, 1], got {self.reacquire_fraction}")
        if min(self.lost_after_s, self.cooldown_s, self.position_spread_m, self.heading_spread_rad,
               self.box_margin, self.track_window_s, self.moving_m_s, self.lost_distance_m,
               self.lost_distance_one_camera_m, self.still_m_s,
               self.still_window_s, self.depth_band_m, self.depth_band_delay_s, self.reach_m, self.reach_m_s,
               self.reach_reset_s, self.reach_agree_s, self.lost_rows_one_camera, self.depth_band_rows, self.reach_rows,
               self.heading_band_rad, self.heading_band_turning_rad) < 0:
            raise ValueError("RecoveryConfig: times, spreads and margins must be >= 0")
        if not (self.depth_band_sigma_m > 0 and 0 < self.depth_band_outlier < 1):
            raise ValueError(f"RecoveryConfig: depth_band_sigma_m must be > 0 and depth_band_outlier in (0, 1), got "
                             f"{self.depth_band_sigma_m}, {self.depth_band_outlier}")
        if not (self.heading_band_sigma_rad > 0 and self.heading_band_window_s > 0):
            raise ValueError(f"RecoveryConfig: heading_band_sigma_rad and heading_band_window_s must be > 0, got "
                             f"{self.heading_band_sigma_rad}, {self.heading_band_window_s}")


def put_rows(target: Any, indices: np.ndarray, source: Any) -> Any:
    """A copy of ``target`` (dataclass of per-particle arrays, nested) with rows ``indices`` taken
    from ``source`` (same type, len(indices) rows)."""
    if is_dataclass(target):
        return type(target)(**{f.name: put_rows(getattr(target, f.name), indices, getattr(source, f.name))
                               for f in fields(target)})
    out = np.array(target, copy=True)
    out[indices] = source
    return out


@dataclass(frozen=True)
class Reacquisition:
    """Where to re-seed: the person's ground position (m), and heading (rad) / speed (m/s) when known."""

    position: np.ndarray
    heading: float | None
    speed: float | None


class LostTrackMonitor:
    """Per frame: detect the person, decide whether the particles are off it, order re-acquisitions.

    Frames are identified by their index; a frame seen again (the filter re-simulates its
    look-ahead window after resampling) gets the decision made the first time."""

    def __init__(self, cameras: list[Camera], config: RecoveryConfig, dt: float,
                 body_height_m: float | None = None) -> None:
        self.cameras = list(cameras)
        self.body_height_m = body_height_m
        self.config = config
        self.dt = float(dt)
        self.track = GroundTrack(dt)
        self._run: dict[int, int] = {}
        self._orders: dict[int, Reacquisition | None] = {}
        self._still: dict[int, bool] = {}
        self._gaps: dict[int, float] = {}   # one camera: the pelvis's ground distance from the feet-row position
        self._row_depths: dict[int, float] = {}   # one camera: the counted feet rows' depth per map row (m)
        self._feet_rows = GroundTrack(dt)   # one camera: the feet-row ground position per frame (None: it does not count)
        self._left_out: dict[int, np.ndarray] = {}   # one camera: feet rows as tall as the body but out of reach
        self._placed = GroundTrack(dt)      # the triangulated ground position per frame (None: not triangulated)
        self._quiet_until = -1
        self._first_frame: int | None = None
        self.reacquisitions = 0

    def _off_person(self, frame: int, detection: PersonDetection, pelvis: np.ndarray,
                    seen: list[list[PersonBlob]], features: dict[str, Any]) -> bool:
        """True when the pelvis is off the triangulated ground position. Without one: when over
        ``track_window_s`` its median ground distance from the feet-row positions exceeds
        ``lost_distance_one_camera_m`` (a drift along the line of sight, which leaves the body on the
        person's image; only frames whose blob is as tall as the body, ``feet_row_height_ratio``, count,
        and at least half the window must), or when it projects outside every widened box of every
        person-sized blob (so a second, larger person in view does not count as losing the one followed).
        Records this frame's feet-row distance for the later frames' medians."""
        if detection.triangulated:
            return bool(np.linalg.norm(pelvis[:2] - detection.position) > self.config.lost_distance_m)
        low, high = self.config.feet_row_height_ratio
        as_tall = self.body_height_m is None or low <= detection.height / self.body_height_m <= high
        counts = (as_tall and not any(ends_on_occlusion(blob, features[blob.camera]) for blob in detection.blobs)
                  and (self._reachable(frame, detection.position, detection.row_depth_m)
                       or self._agreeing(frame, detection.position, detection.row_depth_m, pelvis)))
        self._feet_rows.add(frame, detection.position.copy() if counts else None)
        if counts:
            self._gaps[frame] = float(np.linalg.norm(pelvis[:2] - detection.position))
            self._row_depths[frame] = detection.row_depth_m
        span = self.track.span(self.config.track_window_s)
        window = [f for f in range(frame - span + 1, frame + 1) if f in self._gaps]
        if 2 * len(window) >= span:
            rows = self.config.lost_rows_one_camera * float(np.median([self._row_depths[f] for f in window]))
            if float(np.median([self._gaps[f] for f in window])) > max(self.config.lost_distance_one_camera_m, rows):
                return True
        by_name = {c.name: c for c in self.cameras}
        return not any(on_blob(by_name[blob.camera], pelvis, blob, self.config.box_margin)
                       for blobs in seen for blob in blobs)

    def _reach(self, row_depth_m: float) -> float:
        """How far (m) a feet row whose map row spans ``row_depth_m`` of depth may lie from where it is expected:
        ``reach_m``, or ``reach_rows`` of its rows where farther."""
        return max(self.config.reach_m, self.config.reach_rows * row_depth_m)

    def _reachable(self, frame: int, position: np.ndarray, row_depth_m: float) -> bool:
        """Whether a feet-row ground position (m) at ``frame``, whose map row spans ``row_depth_m`` of depth, is
        within reach of the counted ones (module docstring: ``reach_m`` or ``reach_rows``, ``reach_m_s``,
        ``reach_reset_s``)."""
        cfg = self.config
        reset = int(round(cfg.reach_reset_s / self.dt))
        counted = self._feet_rows.positions
        recent = [f for f, p in counted.items() if p is not None and 0 < frame - f <= reset]
        if not recent:
            return True
        last = max(recent)
        where = self._feet_rows.fitted_position(last, cfg.track_window_s)
        velocity = self._feet_rows.velocity(last, cfg.track_window_s)
        elapsed = (frame - last) * self.dt
        predicted = (counted[last] if where is None else where) + (0.0 if velocity is None else velocity * elapsed)
        return bool(np.linalg.norm(position - predicted) <= self._reach(row_depth_m) + cfg.reach_m_s * elapsed)

    def _agreeing(self, frame: int, position: np.ndarray, row_depth_m: float, pelvis: np.ndarray) -> bool:
        """Whether a feet-row ground position (m) at ``frame`` out of reach of the counted ones lies within
        ``reach_m`` (or ``reach_rows`` map rows of its depth) of the particles' ``pelvis`` and of every feet row
        left out over the last ``reach_agree_s``, one every frame: the person stands there and the counted ones
        were off (a far, low camera's feet row that stepped a row or two and stayed). Legs hidden behind something
        put the row metres behind a pelvis on the person, so those stay out. One camera only: a rig of several
        falls back on one camera's feet row only in frames the others miss, and was measured without it. Records
        ``position`` as left out when it does not agree."""
        cfg = self.config
        span = int(round(cfg.reach_agree_s / self.dt))
        reach = self._reach(row_depth_m)
        agree = (len(self.cameras) == 1 and span > 1 and np.linalg.norm(position - pelvis[:2]) <= reach
                 and all(f in self._left_out and np.linalg.norm(self._left_out[f] - position) <= reach
                         for f in range(frame - span + 1, frame)))
        if not agree:
            self._left_out[frame] = position.copy()
        return agree

    def feet_row_position(self, frame: int) -> np.ndarray | None:
        """One camera: the person's ground position (m, world xy) from ``frame``'s feet row where it counts
        (a reliable blob as tall as the body; decided by ``update``), else None."""
        return self._feet_rows.positions.get(frame)

    def depth_band(self, frame: int) -> tuple[np.ndarray, float] | None:
        """One camera: the depth band at ``frame``, its centre (m, world xy: the feet-row position where it
        counts, ``feet_row_position``) and half width (m: ``depth_band_m``, or ``depth_band_rows`` map rows of
        the feet row's depth if wider), from ``depth_band_delay_s`` after the first frame tracked on; else None."""
        delay = int(round(self.config.depth_band_delay_s / self.dt))
        centre = self.feet_row_position(frame)
        if self._first_frame is None or frame - self._first_frame < delay or centre is None:
            return None
        return centre, max(self.config.depth_band_m, self.config.depth_band_rows * self._row_depths[frame])

    def heading_band(self, frame: int) -> tuple[float, float] | None:
        """One camera: the heading band at ``frame``, its direction (rad: where the counted feet rows moved over
        ``heading_band_window_s``) and half width (rad: ``heading_band_rad``, plus the angle between that direction
        and the window's last half's, plus the angle a map row of the feet row's depth subtends over the distance
        moved), where this frame's feet row counts, the window and its last half move at ``moving_m_s`` or faster
        and turn by at most ``heading_band_turning_rad``, and the person does not stand still; else None."""
        cfg = self.config
        if cfg.heading_band_rad <= 0 or self.still(frame) or self.feet_row_position(frame) is None:
            return None
        whole = self._feet_rows.velocity(frame, cfg.heading_band_window_s)
        recent = self._feet_rows.velocity(frame, 0.5 * cfg.heading_band_window_s)
        if whole is None or recent is None or min(np.linalg.norm(whole), np.linalg.norm(recent)) < cfg.moving_m_s:
            return None
        direction = float(np.arctan2(whole[1], whole[0]))
        turned = abs(float(np.angle(np.exp(1j * (np.arctan2(recent[1], recent[0]) - direction)))))
        if turned > cfg.heading_band_turning_rad:
            return None
        # a far, low camera places the feet in steps of a map row along its view: over a window that moved less
        # than a row's depth the direction is as uncertain as the row is long
        rows = float(np.arctan2(self._row_depths[frame], np.linalg.norm(whole) * cfg.heading_band_window_s))
        return direction, cfg.heading_band_rad + turned + rows

    def placed_position(self, frame: int) -> np.ndarray | None:
        """Where cameras at different angles place the person at ``frame`` (m, world xy: the line fit over
        ``track_window_s`` of the triangulated detections, steadier than one), when ``frame``'s detection was
        triangulated (decided by ``update``); else None."""
        if self._placed.positions.get(frame) is None:
            return None
        return self._placed.fitted_position(frame, self.config.track_window_s)

    @property
    def first_frame(self) -> int | None:
        """The first frame ``update`` saw (None before)."""
        return self._first_frame

    def still(self, frame: int) -> bool:
        """Whether the person stood still at ``frame`` (decided by ``update``; False if not yet)."""
        return self._still.get(frame, False)

    def update(self, frame: int, features: list[Any], pelvis: np.ndarray) -> Reacquisition | None:
        """The re-acquisition to make at ``frame`` (None: none), given the particles' mean pelvis (3,);
        also decides ``still(frame)``."""
        if frame in self._orders:
            return self._orders[frame]
        if self._first_frame is None:
            self._first_frame = frame
        cfg = self.config
        seen = [person_blobs(f, c.name) for f, c in zip(features, self.cameras)]     # once: used twice below
        detection = locate_person(seen, self.cameras, near=pelvis)
        reliable = detection is not None and wholly_in_view(detection, self.cameras)
        self.track.add(frame, detection.position if reliable else None)
        self._placed.add(frame, detection.position if reliable and detection.triangulated else None)
        velocity = self.track.velocity(frame, cfg.track_window_s)
        speed = None if velocity is None else float(np.linalg.norm(velocity))
        recent = self.track.velocity(frame, cfg.still_window_s)
        recent_speed = None if recent is None else float(np.linalg.norm(recent))
        was_still = self._still.get(frame - 1, False)
        # hysteresis: a stop starts below still_m_s and lasts until the track moves at moving_m_s
        self._still[frame] = cfg.hold_still and recent_speed is not None and (
            recent_speed < (cfg.moving_m_s if was_still else cfg.still_m_s))
        by_camera = {c.name: f for c, f in zip(self.cameras, features)}
        # a body whose pelvis has left every image is a person walking out of view (``inference.visibility``:
        # the track ends), not a track to move onto whoever else is in view
        off = (cfg.reacquire and reliable and self._off_person(frame, detection, pelvis, seen, by_camera)
               and any(bool(camera.in_image(pelvis)) for camera in self.cameras))
        self._run[frame] = self._run.get(frame - 1, 0) + 1 if off else 0
        order = None
        if off and self._run[frame] * self.dt >= cfg.lost_after_s and frame >= self._quiet_until:
            moving = speed is not None and speed >= cfg.moving_m_s
            order = Reacquisition(detection.position.copy(),
                                  float(np.arctan2(velocity[1], velocity[0])) if moving else None,
                                  float(np.linalg.norm(velocity)) if moving else None)
            self._quiet_until = frame + max(1, int(round(self.config.cooldown_s / self.dt)))
            self.reacquisitions += 1
        self._orders[frame] = order
        # keep a few seconds of history (the tracks keep their own)
        for store in (self._run, self._orders, self._still, self._gaps, self._row_depths, self._left_out):
            for old in [f for f in store if f < frame - 300]:
                del store[old]
        return order
