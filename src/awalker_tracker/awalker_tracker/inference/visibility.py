"""Whether the tracked person is in view, per camera and frame, and when a track ends.

The walker only walks: once the person has left the images it keeps walking, out of the picture and on,
and every step it takes there is invented. So each completed frame (``Tracker``) asks, of every camera,
two questions about the posterior's weighted-mean body:

- **inside**: does its pelvis, and do at least ``min_inside_fraction`` of its 13 markers, project inside
  the image (in front of the camera)? A person half through the image border still counts; one whose
  pelvis is out (walking out at the side, or away out of the top of a camera looking down) does not.
- **supported**: does its pelvis lie on a person-sized foreground blob of that camera's image
  (``vision.detection.person_blobs``, the box widened by ``support_margin`` of its size on each side)?
  A body standing where the images see nobody is not followed.

The person is in view of a camera where both hold. Once the person has been in view of some camera, a run
of ``end_after_s`` of frames in view of none ends the track (``ViewMonitor``), with the reason: left the
view of every camera (at the last of those frames no camera has the body inside) or no longer supported by
the images. The frames of
that run were published, flagged out of view; nothing after it is. A person standing still stays a blob
(the features learn the background robustly, ``vision.background``), so a stop inside the view ends
nothing.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.vision.detection import on_blob, person_blobs

PELVIS = MARKER_NAMES.index("pelvis")
LEFT_EVERY_VIEW = "left the view of every camera"
NOT_SUPPORTED = "no longer supported by the images"


@dataclass(frozen=True)
class ViewConfig:
    """When the person counts as in view, and how long out of view ends the track."""

    min_inside_fraction: float = 0.5   # share of the body's markers that must project inside the image
    support_margin: float = 0.25       # blob boxes are widened by this share of their size on each side
    end_after_s: float = 0.3           # s: out of every camera's view this long ends the track (0: never)

    def __post_init__(self) -> None:
        if not (0.0 < self.min_inside_fraction <= 1.0 and self.support_margin >= 0.0 and self.end_after_s >= 0.0):
            raise ValueError(f"ViewConfig: min_inside_fraction must lie in (0, 1], support_margin and end_after_s "
                             f"be >= 0, got {self}")


@dataclass(frozen=True)
class CameraView:
    """One camera's view of the tracked body at one frame."""

    camera: str
    inside: bool       # enough of the body projects inside the image
    supported: bool    # its pelvis lies on a person-sized foreground blob

    @property
    def in_view(self) -> bool:
        return self.inside and self.supported


def camera_views(cameras: Sequence[Any], features: Sequence[Any], markers: np.ndarray,
                 config: ViewConfig = ViewConfig()) -> tuple[CameraView, ...]:
    """Each camera's view of the body ``markers`` (M, 3) world (m), MARKER_NAMES order, given the frame's
    features per camera (same order)."""
    views = []
    pelvis = markers[PELVIS]
    for camera, item in zip(cameras, features):
        seen = camera.in_image(markers)
        inside = bool(seen[PELVIS] and np.mean(seen) >= config.min_inside_fraction)
        supported = inside and any(on_blob(camera, pelvis, blob, config.support_margin)
                                   for blob in person_blobs(item, camera.name))
        views.append(CameraView(camera.name, inside, supported))
    return tuple(views)


@dataclass(frozen=True)
class TrackEnd:
    """Where and why a track ended."""

    frame_index: int               # the track's last frame (published, out of view)
    stamp_ns: int
    last_in_view_frame: int        # the last frame the person was in view of some camera
    reason: str                    # LEFT_EVERY_VIEW or NOT_SUPPORTED


class ViewMonitor:
    """Counts the completed frames out of every camera's view; ``update`` answers the ``TrackEnd`` once a run of
    ``end_after_s`` follows a frame in view (module docstring)."""

    def __init__(self, dt: float, config: ViewConfig = ViewConfig()) -> None:
        self.config = config
        self.end_frames = int(np.ceil(config.end_after_s / float(dt) - 1e-9)) if config.end_after_s > 0 else 0
        self.last_in_view: int | None = None
        self.out_of_view = 0           # frames in the current run out of every view

    def update(self, frame_index: int, stamp_ns: int, views: Sequence[CameraView]) -> TrackEnd | None:
        if not views:
            return None
        if any(v.in_view for v in views):
            self.last_in_view, self.out_of_view = int(frame_index), 0
            return None
        if self.last_in_view is None:
            return None                # not yet seen (a hand start before the person came in): nothing ends
        self.out_of_view += 1
        if self.end_frames and self.out_of_view >= self.end_frames:
            return TrackEnd(int(frame_index), int(stamp_ns), self.last_in_view,
                            NOT_SUPPORTED if any(v.inside for v in views) else LEFT_EVERY_VIEW)
        return None
