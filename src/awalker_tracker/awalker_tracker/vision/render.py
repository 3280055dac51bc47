"""Per-pixel ray casting of the body: part labels and depth with self-occlusion (the foreground is learned
from the body's labels at the start pose, ``vision.foreground``). Test images are drawn from the same hits
by ``awalker_tools.model_render``.

Ray casting, exact up to a bisection tolerance: every pixel's ray (through the distorted
camera model, ``Camera.pixels_to_normalised``) is intersected with each part's tapered elliptical
cylinder (side and both end caps) in the part's own frame. Within the part's slab
0 <= z <= length and its bounding circular cylinder, the ray is sampled at ``_SAMPLES``
points for the first one inside the part, then the entry is refined by bisection. Parts
are convex, so a ray enters a part once; a z-buffer over parts resolves self-occlusion.
Depth is the camera-frame z (m) of the visible surface (``inf`` where no part is seen).

Only pixels inside each part's projected bounding box are cast; a 640x480 frame with a
person at 3-5 m takes ~20-40 ms (``benchmarks/bench_render.py``).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from awalker_tracker.model.body import BodyDescription, BodySegments, PartShape
from awalker_tracker.vision.camera import Camera

_SAMPLES = 24
_BISECTIONS = 12


@lru_cache(maxsize=16)
def pixel_rays(camera: Camera) -> np.ndarray:
    """Undistorted normalised image coordinates (H, W, 2) of every pixel centre (cached per camera)."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float64)
    normalised = camera.pixels_to_normalised(np.stack([u, v], axis=-1))
    out = normalised.reshape(camera.height, camera.width, 2)
    out.setflags(write=False)
    return out


@dataclass
class RenderResult:
    """labels (H, W) int16 part index or -1; depth (H, W) m (inf = background);
    local (H, W, 3) hit point in the part's frame (m), for texturing and shading a picture."""

    labels: np.ndarray
    depth: np.ndarray
    local: np.ndarray


def one_body(segments: BodySegments) -> tuple[np.ndarray, np.ndarray]:
    """The part origins (P, 3) m and frames (P, 3, 3) of one body's segments (a batch of one or none)."""
    origin, rotation = np.asarray(segments.origin), np.asarray(segments.rotation)
    if origin.ndim == 3:
        if origin.shape[0] != 1:
            raise ValueError(f"render: expected the segments of one body, got {origin.shape[0]}")
        origin, rotation = origin[0], rotation[0]
    if origin.ndim != 2 or origin.shape[1] != 3 or rotation.shape != origin.shape + (3,):
        raise ValueError(f"render: segment origins must be (P, 3), got {origin.shape}")
    return origin, rotation


def _bounding_box(part: PartShape, origin: np.ndarray, rotation: np.ndarray, camera: Camera) -> tuple[int, int, int, int] | None:
    """Pixel bounds (u0, u1, v0, v1) of a part, None if it cannot be seen."""
    r = part.max_radius
    corners = np.array([[x, y, z] for x in (-r, r) for y in (-r, r) for z in (0.0, part.length)])
    world = origin + corners @ rotation.T
    uv, depth = camera.project(world)
    if np.all(depth <= 0):
        return None
    if np.any(depth <= 1e-6) or not np.all(np.isfinite(uv)):
        return 0, camera.width, 0, camera.height
    u0, v0 = np.floor(uv.min(axis=0)).astype(int) - 2
    u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + 3
    u0, u1 = max(u0, 0), min(u1, camera.width)
    v0, v1 = max(v0, 0), min(v1, camera.height)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


def _inside(part: PartShape, points: np.ndarray) -> np.ndarray:
    """Implicit function (<= 0 inside) of the tapered elliptical side surface at local points (..., 3)."""
    s = np.clip(points[..., 2] / part.length, 0.0, 1.0)[..., None]
    radii = part.radii_start + (part.radii_end - part.radii_start) * s
    return np.sum((points[..., :2] / radii) ** 2, axis=-1) - 1.0


def _cast_part(part: PartShape, origin: np.ndarray, rotation: np.ndarray, camera_position: np.ndarray,
               directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry depth t (M,) (inf on a miss) and local entry points (M, 3) of rays C + t d."""
    o = (camera_position - origin) @ rotation          # ray origin in the part frame
    d = directions @ rotation                          # (M, 3) ray directions in the part frame
    m = d.shape[0]
    t_lo = np.full(m, 1e-6)
    t_hi = np.full(m, np.inf)
    # Slab 0 <= z <= length.
    dz = d[:, 2]
    moving = np.abs(dz) > 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(moving, (0.0 - o[2]) / dz, -np.inf)
        t1 = np.where(moving, (part.length - o[2]) / dz, np.inf)
    inside_slab = (o[2] >= 0) & (o[2] <= part.length)
    t_lo = np.maximum(t_lo, np.where(moving, np.minimum(t0, t1), np.where(inside_slab, -np.inf, np.inf)))
    t_hi = np.minimum(t_hi, np.where(moving, np.maximum(t0, t1), np.where(inside_slab, np.inf, -np.inf)))
    # Bounding circular cylinder x^2 + y^2 <= r^2.
    r = part.max_radius * 1.001
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = o[0] * d[:, 0] + o[1] * d[:, 1]
    c = o[0] ** 2 + o[1] ** 2 - r * r
    disc = b * b - a * c
    axial = a < 1e-15
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.maximum(disc, 0.0))
        c0 = np.where(axial, np.where(c <= 0, -np.inf, np.inf), (-b - root) / a)
        c1 = np.where(axial, np.where(c <= 0, np.inf, -np.inf), (-b + root) / a)
    c0 = np.where(~axial & (disc < 0), np.inf, c0)
    c1 = np.where(~axial & (disc < 0), -np.inf, c1)
    t_lo = np.maximum(t_lo, c0)
    t_hi = np.minimum(t_hi, c1)
    depth = np.full(m, np.inf)
    local = np.zeros((m, 3))
    candidate = np.flatnonzero(t_lo < t_hi)
    if candidate.size == 0:
        return depth, local
    o_, d_ = o, d[candidate]
    lo, hi = t_lo[candidate], t_hi[candidate]
    fractions = np.linspace(0.0, 1.0, _SAMPLES + 1)
    ts = lo[:, None] + (hi - lo)[:, None] * fractions[None, :]       # (K, S+1)
    values = _inside(part, o_ + ts[..., None] * d_[:, None, :])
    inside = values <= 0
    hit = inside.any(axis=1)
    first = np.argmax(inside, axis=1)
    rows = np.flatnonzero(hit)
    k = first[rows]
    t_in = ts[rows, k]
    at_entry = k == 0                                                   # entered through a cap or at t_lo
    t_out = np.where(at_entry, t_in, ts[rows, np.maximum(k - 1, 0)])    # outside bracket
    for _ in range(_BISECTIONS):
        mid = 0.5 * (t_in + t_out)
        mid_inside = _inside(part, o_ + mid[:, None] * d_[rows]) <= 0
        t_in = np.where(mid_inside & ~at_entry, mid, t_in)
        t_out = np.where(~mid_inside & ~at_entry, mid, t_out)
    idx = candidate[rows]
    depth[idx] = t_in
    local[idx] = o_ + t_in[:, None] * d_[rows]
    return depth, local


def render(body: BodyDescription, segments: BodySegments, camera: Camera) -> RenderResult:
    """Ray-cast one body into one camera: labels, depth and local hit points per pixel."""
    origin, rotation = one_body(segments)
    return render_parts(body.parts, origin, rotation, camera)


def render_parts(parts: tuple[PartShape, ...], origin: np.ndarray, rotation: np.ndarray,
                 camera: Camera) -> RenderResult:
    """Ray-cast any tapered elliptical cylinders (origins (P, 3) m, frames (P, 3, 3)); labels index ``parts``."""
    rays = pixel_rays(camera)
    labels = np.full((camera.height, camera.width), -1, np.int16)
    depth = np.full((camera.height, camera.width), np.inf)
    local = np.zeros((camera.height, camera.width, 3))
    for index, part in enumerate(parts):
        box = _bounding_box(part, origin[index], rotation[index], camera)
        if box is None:
            continue
        u0, u1, v0, v1 = box
        xy = rays[v0:v1, u0:u1].reshape(-1, 2)
        directions = np.column_stack([xy, np.ones(len(xy))]) @ camera.rotation.T  # world, z_cam = 1
        t, hit_local = _cast_part(part, origin[index], rotation[index], camera.position, directions)
        t = t.reshape(v1 - v0, u1 - u0)
        window = depth[v0:v1, u0:u1]
        closer = t < window
        window[closer] = t[closer]
        labels[v0:v1, u0:u1][closer] = index
        local[v0:v1, u0:u1][closer] = hit_local.reshape(v1 - v0, u1 - u0, 3)[closer]
    return RenderResult(labels, depth, local)


def render_labels(body: BodyDescription, segments: BodySegments, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Part index per pixel (H, W) int16 (-1 = background, else index into ``PART_NAMES``) and
    depth (H, W) in metres along the optical axis (inf = background), with self-occlusion."""
    result = render(body, segments, camera)
    return result.labels, result.depth
