"""Silhouette extent: where the body's feet and head top fall in the image against the person's blob.

The appearance and flow terms of ``vision.likelihood`` look only at pixels *inside* the model's
silhouette. With one camera that leaves depth weakly observed: a body a little farther away
projects smaller and still lies wholly on the person. The person's foreground blob
(``vision.detection.person_blob``) gives two image rows the model must reproduce: its lowest row
(the feet on the floor; through the calibrated camera and the ground plane, that row fixes the
distance) and its highest row (the top of the head; with the body's height, the scale). Per state
and camera the residuals are the model's lowest projected foot marker (heel or toe, either foot)
and its head top (end of the head part) minus the blob's rows, in units of ``sigma_fraction`` of
the blob's height, scored with a Cauchy (heavy-tailed) density so that a blob spoiled by a shadow,
a bag or a second person costs a bounded amount:

    log p = -sum_rows log(1 + (dv / (sigma_fraction * blob_height))^2)

Cameras without a blob, or whose blob touches the image top or bottom (the rows are then not the
body's), contribute nothing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from awalker_tracker.model.body import MARKER_NAMES, BodySegments, PartShape
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import PersonBlob

FOOT_MARKERS = [MARKER_NAMES.index(n) for n in ("left_heel", "right_heel", "left_toe", "right_toe")]


@dataclass(frozen=True)
class ExtentConfig:
    """Weight (nats per unit of the Cauchy term, before tempering) and width of the extent term."""

    weight: float = 0.0              # off by default: see the README (measured no gain on our renders)
    sigma_fraction: float = 0.03     # residual scale: this fraction of the blob's height (px)
    border_px: float = 2.0           # blobs this close to the image top or bottom are not used
    head: bool = False               # also score the head row (hair, hats and the blob's smoothing bias it)

    def __post_init__(self) -> None:
        if self.weight < 0 or not self.sigma_fraction > 0 or self.border_px < 0:
            raise ValueError("ExtentConfig: weight and border_px must be >= 0 and sigma_fraction > 0")


def usable(blob: PersonBlob | None, camera: Camera, config: ExtentConfig) -> bool:
    """The blob's top and bottom rows are the person's (not cut by the image border)."""
    return (blob is not None and blob.box[1] > config.border_px
            and blob.box[3] < camera.height - 1 - config.border_px)


def extent_log_likelihood(markers: np.ndarray, segments: BodySegments, parts: tuple[PartShape, ...],
                          cameras: list[Camera], blobs: list[PersonBlob | None],
                          config: ExtentConfig = ExtentConfig()) -> np.ndarray:
    """(N,) log-likelihood of the feet and head rows of N posed bodies (markers (N, 13, 3) m) over the
    cameras' person blobs (one per camera, None: no person seen)."""
    n = markers.shape[0]
    total = np.zeros(n)
    head = [p.name for p in parts].index("head")
    head_top = segments.end_points(parts)[:, head]                       # (N, 3)
    feet = markers[:, FOOT_MARKERS]                                       # (N, 4, 3)
    for camera, blob in zip(cameras, blobs):
        if not usable(blob, camera, config):
            continue
        scale = config.sigma_fraction * max(blob.box[3] - blob.box[1], 1.0)
        feet_uv, _ = camera.project(feet)
        head_uv, _ = camera.project(head_top)
        lowest = np.nanmax(feet_uv[..., 1], axis=1) if np.isfinite(feet_uv[..., 1]).any() else np.full(n, np.nan)
        rows = [lowest - blob.box[3]] + ([head_uv[:, 1] - blob.box[1]] if config.head else [])
        rows = np.stack(rows, axis=1) / scale
        # feet or head behind the camera: the cost of a 100-sigma miss
        cost = np.log1p(np.square(np.nan_to_num(rows, nan=100.0)))
        total -= config.weight * cost.sum(axis=1)
    return total
