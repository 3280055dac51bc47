"""Overlays of a 3D body on camera frames, for people to look at (PNG)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import MARKER_NAMES, SKELETON_EDGES, BodyDescription, BodySegments
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import render_labels

from awalker_tools.model_render import DEFAULT_COLOURS

_INDEX = {n: i for i, n in enumerate(MARKER_NAMES)}
_LEFT_COLOUR = (60, 220, 60)
_RIGHT_COLOUR = (240, 80, 240)
_CENTRE_COLOUR = (250, 230, 40)


def draw_body(
    image: np.ndarray,
    markers: np.ndarray,
    camera: Camera,
    segments: BodySegments | None = None,
    body: BodyDescription | None = None,
    alpha: float = 0.35,
    thickness: int = 2,
) -> np.ndarray:
    """A copy of ``image`` (H, W, 3) uint8 RGB with the skeleton of ``markers`` (13, 3) (world m)
    drawn as lines (left limbs green, right magenta); with ``segments`` and ``body``, the
    rendered parts are also blended in at ``alpha`` with their outlines."""
    if image.shape[:2] != (camera.height, camera.width):
        raise ValueError(f"draw_body: image is {image.shape[:2]}, camera {camera.name} is "
                         f"{(camera.height, camera.width)}")
    out = np.ascontiguousarray(image.copy())
    if segments is not None and body is not None:
        labels, _ = render_labels(body, segments, camera)
        mask = labels >= 0
        if mask.any():
            fill = DEFAULT_COLOURS[labels[mask]]
            out[mask] = np.clip((1 - alpha) * out[mask] + alpha * fill, 0, 255).astype(np.uint8)
            edges = cv2.morphologyEx(labels.astype(np.int32).astype(np.float32), cv2.MORPH_GRADIENT,
                                     np.ones((3, 3), np.uint8)) > 0
            out[edges] = (255, 255, 255)
    uv, depth = camera.project(np.asarray(markers, float))
    visible = depth > 0
    for a, b in SKELETON_EDGES:
        i, j = _INDEX[a], _INDEX[b]
        if not (visible[i] and visible[j]):
            continue
        colour = _LEFT_COLOUR if b.startswith("left") else _RIGHT_COLOUR if b.startswith("right") else _CENTRE_COLOUR
        p, q = (tuple(int(round(c)) for c in uv[k]) for k in (i, j))
        cv2.line(out, p, q, colour, thickness, cv2.LINE_AA)
    for k in np.flatnonzero(visible):
        cv2.circle(out, tuple(int(round(c)) for c in uv[k]), thickness + 1, (255, 255, 255), -1, cv2.LINE_AA)
    return out


def save_overlay_png(path: str | Path, image: np.ndarray, markers: np.ndarray, camera: Camera,
                     segments: BodySegments | None = None, body: BodyDescription | None = None) -> Path:
    """Write ``draw_body(...)`` as a PNG; returns the path."""
    path = Path(path)
    drawn = draw_body(image, markers, camera, segments, body)
    if not cv2.imwrite(str(path), cv2.cvtColor(drawn, cv2.COLOR_RGB2BGR)):
        raise InputError(f"{path}: cannot write PNG overlay")
    return path
