"""RGB pictures of the tracker's own body model, for tests and synthetic sequences: per-part colour, a
check texture on the part surface and view-dependent shading over a background, from the core's ray casting
(``awalker_tracker.vision.render``: labels, depth and each pixel's hit point on its part)."""
from __future__ import annotations

import numpy as np

from awalker_tracker.model.body import BodyDescription, BodySegments
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import RenderResult, one_body, render

# Default appearance: one base colour (RGB) per part and a texture period (m) along its axis.
DEFAULT_COLOURS = np.array([
    [200, 60, 50],    # torso: red shirt
    [225, 180, 150],  # head: skin
    [40, 60, 140], [40, 60, 140],    # upper legs: blue trousers
    [40, 60, 140], [40, 60, 140],    # lower legs
    [50, 40, 35], [50, 40, 35],      # feet: dark shoes
], dtype=float)


def render_rgb(body: BodyDescription, segments: BodySegments, camera: Camera, background: np.ndarray,
               colours: np.ndarray | None = None, texture_period: float = 0.06,
               result: RenderResult | None = None) -> np.ndarray:
    """The body drawn over ``background`` (H, W, 3) uint8 RGB: per-part colour, a stripe/check
    texture of period ``texture_period`` (m) on the part surface, and view-dependent shading."""
    if background.shape != (camera.height, camera.width, 3):
        raise ValueError(f"render_rgb: background must be ({camera.height}, {camera.width}, 3), got {background.shape}")
    result = result or render(body, segments, camera)
    colours = DEFAULT_COLOURS if colours is None else np.asarray(colours, float)
    image = background.copy()
    mask = result.labels >= 0
    if not mask.any():
        return image
    label = result.labels[mask].astype(int)
    local = result.local[mask]
    parts = body.parts
    lengths = np.array([p.length for p in parts])[label]
    r0 = np.array([p.radii_start for p in parts])[label]
    r1 = np.array([p.radii_end for p in parts])[label]
    radii = r0 + (r1 - r0) * np.clip(local[:, 2] / lengths, 0, 1)[:, None]
    # Texture: stripes along the axis crossed with stripes around it (a soft check pattern).
    around = np.arctan2(local[:, 1] / radii[:, 1], local[:, 0] / radii[:, 0])
    along = np.floor(local[:, 2] / texture_period)
    ring = np.floor(around / (np.pi / 4))
    check = (along + ring) % 2
    texture = 0.8 + 0.2 * check
    # Shading: surface normal of the elliptical side against the viewing ray.
    normal_local = np.column_stack([local[:, 0] / radii[:, 0] ** 2, local[:, 1] / radii[:, 1] ** 2,
                                    np.zeros(len(label))])
    origin, rotation = one_body(segments)
    normal = np.einsum("kij,kj->ki", rotation[label], normal_local)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    world = origin[label] + np.einsum("kij,kj->ki", rotation[label], local)
    view = camera.position - world
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    shade = 0.45 + 0.55 * np.abs(np.sum(normal * view, axis=1))
    on_cap = (local[:, 2] <= 1e-6) | (local[:, 2] >= lengths - 1e-6)
    shade = np.where(on_cap, 0.7, shade)
    image[mask] = np.clip(colours[label] * (texture * shade)[:, None], 0, 255).astype(np.uint8)
    return image
