"""Batched image log-likelihood of N body poses over C cameras (paper Sec. 5.1, eq. 9-12).

For each state, camera and part, the part's **silhouette plane** is the plane through its axis
perpendicular to the viewing direction; its outline in that plane is the quad start +- h0 w,
end +- h1 w, where w = unit(axis x view) and h = sqrt((r0 (w.e0))^2 + (r1 (w.e1))^2) is the
half-width of the elliptical cross-section seen along the view (its support function). Only
the 4 quad corners are projected (exactly, with distortion); a fixed grid of
``points_along x points_across`` sample points inside the quad is interpolated bilinearly
(the quad is nearly fronto-parallel, so the error is a small fraction of a pixel). The sample
points thus cover the part's projected silhouette uniformly.

Appearance (eq. 10-11, footnote 1): the sum of foreground/background log-likelihood ratios
over the pixels of part i is approximated by (area_i / K) * sum_k llr(point k); eq. 11's
weight w_i is 1 / (expected area of part i): its side-on area (length x mean diameter) at
the median depth of the part over the N states (so each part contributes about its mean
ratio, scaled by how large it appears in this state).
The ratio of the part's class is looked up (nearest map pixel) in ``FrameFeatures.llr``.

Flow (eq. 9): each sample point's predicted image motion u is the motion of the same
part-local point from ``prev_segments`` to ``segments``; it is compared with the measured flow
v of the grid cell it falls in: log p(v | u) - log p(v | 0), i.e. relative to the background's
zero-motion model (the background cells' terms are common to all states and cancel).

Visibility: points outside the image, behind the camera, under the occlusion mask, on invalid
flow cells (flow term only), or hidden by a nearer part are dropped. Self-occlusion is an
analytic per-state test: the legs and feet of one side against the legs and feet of the other
side and (for the upper legs) the torso, each occluder a projected tapered band around its
axis; a point is hidden when it lies within the band and behind the occluder's axis depth.
The test is made at the axis points of each row of samples and shared across the row.
Cameras are conditionally independent: their terms add (eq. 12).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from awalker_tracker.model.body import BodySegments, PartShape
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.features import FrameFeatures, _cell_mask, _map_mask
from awalker_tracker.vision.flow import STUDENT_T_DOF


@dataclass(frozen=True)
class LikelihoodConfig:
    """Sampling density and term weights of the image likelihood."""

    points_along: int = 6           # sample rows along each part's axis
    points_across: int = 3          # samples per row across the silhouette
    appearance_weight: float = 1.0  # multiplies each part's mean log-likelihood ratio
    flow_weight: float = 1.0        # multiplies each part's mean flow log-ratio
    self_occlusion: bool = True

    def __post_init__(self) -> None:
        if self.points_along < 1 or self.points_across < 1:
            raise ValueError("LikelihoodConfig: points_along and points_across must be >= 1")


def _bilinear_weights(along: int, across: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights (K, 4) of corners [start-, start+, end-, end+] and the (t, s') of each point."""
    t = (np.arange(along) + 0.5) / along
    s = (np.arange(across) + 0.5) / across
    tt, ss = np.meshgrid(t, s, indexing="ij")
    tt, ss = tt.ravel(), ss.ravel()
    weights = np.stack([(1 - tt) * (1 - ss), (1 - tt) * ss, tt * (1 - ss), tt * ss], axis=1)
    return weights.astype(np.float32), tt.astype(np.float32), ss.astype(np.float32)


def occluder_table(parts: tuple[PartShape, ...]) -> np.ndarray:
    """(P, 4) indices of the parts that may hide each part (-1 = none): a left leg part by the right
    leg parts and vice versa; upper legs also by the torso. Others: none."""
    names = [p.name for p in parts]
    table = np.full((len(parts), 4), -1, np.int64)
    for i, name in enumerate(names):
        for side, other in (("left_", "right_"), ("right_", "left_")):
            if name.startswith(side):
                cands = [j for j, n in enumerate(names) if n.startswith(other)]
                if name.endswith("upper_leg") and "torso" in names:
                    cands.append(names.index("torso"))
                table[i, : len(cands[:4])] = cands[:4]
    return table


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(norm, 1e-12), norm[..., 0]


def silhouette_corners(parts: tuple[PartShape, ...], segments: BodySegments, camera: Camera) -> np.ndarray:
    """Part-local corners (N, P, 4, 3) of each part's silhouette quad seen from ``camera``."""
    origin = np.asarray(segments.origin)
    rot = np.asarray(segments.rotation)
    lengths = np.array([p.length for p in parts])
    r_start = np.array([p.radii_start for p in parts])     # (P, 2)
    r_end = np.array([p.radii_end for p in parts])
    axis = rot[..., :, 2]
    centre = origin + 0.5 * lengths[:, None] * axis
    lateral, norm = _unit(np.cross(axis, camera.position - centre))
    degenerate = norm < 1e-9                                 # looking along the axis
    lateral = np.where(degenerate[..., None], rot[..., :, 0], lateral)
    # Lateral direction in the part frame (its ellipse-axis components).
    c0 = np.einsum("npi,npi->np", lateral, rot[..., :, 0])
    c1 = np.einsum("npi,npi->np", lateral, rot[..., :, 1])
    h0 = np.sqrt((r_start[:, 0] * c0) ** 2 + (r_start[:, 1] * c1) ** 2)
    h1 = np.sqrt((r_end[:, 0] * c0) ** 2 + (r_end[:, 1] * c1) ** 2)
    unit_local = np.stack([c0, c1, np.zeros_like(c0)], axis=-1)     # (N, P, 3)
    z = np.zeros(origin.shape[:2] + (3,))
    z_end = z.copy()
    z_end[..., 2] = lengths
    return np.stack([z - h0[..., None] * unit_local, z + h0[..., None] * unit_local,
                     z_end - h1[..., None] * unit_local, z_end + h1[..., None] * unit_local], axis=2)


def _to_world(segments: BodySegments, local: np.ndarray) -> np.ndarray:
    return segments.origin[:, :, None, :] + np.einsum("npij,npcj->npci", segments.rotation, local)


def camera_log_likelihood(parts: tuple[PartShape, ...], segments: BodySegments, prev_segments: BodySegments,
                          camera: Camera, features: FrameFeatures, occlusion_mask: np.ndarray | None = None,
                          config: LikelihoodConfig = LikelihoodConfig()) -> np.ndarray:
    """Log-likelihood (N,) of one camera's features (see the module docstring)."""
    n, p = segments.origin.shape[:2]
    if p != len(parts):
        raise ValueError(f"likelihood: segments have {p} parts, body has {len(parts)}")
    if (features.image_width, features.image_height) != (camera.width, camera.height):
        raise ValueError(f"likelihood: features of camera {camera.name} are {features.image_width}x"
                         f"{features.image_height}, calibration says {camera.width}x{camera.height}")
    class_index = np.array([features.classes.index(part.part_class) for part in parts])
    weights, _, _ = _bilinear_weights(config.points_along, config.points_across)
    k = weights.shape[0]
    local = silhouette_corners(parts, segments, camera)
    uv, depth = camera.project(_to_world(segments, local))           # (N, P, 4, 2), (N, P, 4)
    uv_prev, _ = camera.project(_to_world(prev_segments, local))
    uv = uv.astype(np.float32)
    depth = depth.astype(np.float32)
    # Sample points (N, P, K, 2) and their depths (axis depth at their row).
    points = np.einsum("npcx,kc->npkx", uv, weights)
    motion = points - np.einsum("npcx,kc->npkx", uv_prev.astype(np.float32), weights)
    d_start = 0.5 * (depth[..., 0] + depth[..., 1])
    d_end = 0.5 * (depth[..., 2] + depth[..., 3])
    ok = (d_start > 0)[..., None] & (d_end > 0)[..., None] & np.all(np.isfinite(points), axis=-1)
    ok &= (points[..., 0] >= 0) & (points[..., 0] < camera.width) & (points[..., 1] >= 0) & (points[..., 1] < camera.height)
    if config.self_occlusion:
        ok &= ~_self_occluded(parts, uv, d_start, d_end, config)
    # Projected areas (px^2) and eq. 11 weights: 1 / expected area, the side-on area of the
    # part (length x mean diameter) at the states' median depth of the part.
    q = uv[..., [0, 1, 3, 2], :]
    area = 0.5 * np.abs(np.sum(q[..., 0] * np.roll(q[..., 1], -1, axis=-1) - np.roll(q[..., 0], -1, axis=-1) * q[..., 1], axis=-1))
    area = np.where(np.isfinite(area), area, 0.0)
    size = np.array([p.length * (np.mean(p.radii_start) + np.mean(p.radii_end)) for p in parts])  # m^2
    median_depth = np.maximum(np.median(0.5 * (d_start + d_end), axis=0), 1e-3)       # (P,)
    expected = np.maximum(camera.K[0, 0] * camera.K[1, 1] * size / median_depth ** 2, 1.0)
    part_scale = (area / expected) / k                                  # (N, P)
    # Appearance.
    llr = features.llr
    mask_map = _map_mask(occlusion_mask, features.downsample, features.map_shape)
    if mask_map is not None:
        llr = np.where(mask_map[None], np.float32(0), llr)
    h, w = features.map_shape
    safe = np.where(ok[..., None], points, 0.0)
    col = np.minimum((safe[..., 0] / features.downsample).astype(np.int32), w - 1)
    row = np.minimum((safe[..., 1] / features.downsample).astype(np.int32), h - 1)
    flat = (class_index[None, :, None] * (h * w) + row * w + col)
    values = np.where(ok, llr.reshape(-1)[flat], np.float32(0))
    total = config.appearance_weight * np.sum(part_scale * values.sum(axis=-1), axis=-1, dtype=np.float64)
    # Flow.
    grid = features.flow
    valid = grid.valid
    cell_mask = _cell_mask(occlusion_mask, *grid.shape, grid.cell_size)
    if cell_mask is not None:
        valid = valid & ~cell_mask
    if config.flow_weight > 0 and valid.any():
        rows, cols = grid.shape
        info = np.linalg.inv(grid.covariance.astype(np.float64)).astype(np.float32)
        v = grid.flow
        e0 = np.einsum("rci,rcij,rcj->rc", v, info, v) / STUDENT_T_DOF
        ccol = (safe[..., 0] / grid.cell_size).astype(np.int32)
        crow = (safe[..., 1] / grid.cell_size).astype(np.int32)
        in_grid = ok & (ccol < cols) & (crow < rows)
        cell = np.where(in_grid, np.minimum(crow, rows - 1) * cols + np.minimum(ccol, cols - 1), 0)
        use = in_grid & valid.reshape(-1)[cell]
        d = v.reshape(-1, 2)[cell] - motion                             # (N, P, K, 2)
        i = info.reshape(-1, 4)[cell]
        e2 = (d[..., 0] * (i[..., 0] * d[..., 0] + 2 * i[..., 1] * d[..., 1]) + i[..., 3] * d[..., 1] ** 2) / STUDENT_T_DOF
        ratio = -0.5 * (STUDENT_T_DOF + 2) * (np.log1p(np.where(use, e2, 0)) - np.log1p(np.where(use, e0.reshape(-1)[cell], 0)))
        total += config.flow_weight * np.sum(part_scale * ratio.sum(axis=-1), axis=-1, dtype=np.float64)
    return total


def _self_occluded(parts: tuple[PartShape, ...], uv: np.ndarray, d_start: np.ndarray, d_end: np.ndarray,
                   config: LikelihoodConfig) -> np.ndarray:
    """(N, P, K) True where a sample point is hidden by another part (see the module docstring)."""
    n, p = uv.shape[:2]
    along, across = config.points_along, config.points_across
    hidden = np.zeros((n, p, along), bool)
    table = occluder_table(parts)
    who = np.flatnonzero(np.any(table >= 0, axis=1))
    if who.size == 0:
        return np.zeros((n, p, along * across), bool)
    a = 0.5 * (uv[..., 0, :] + uv[..., 1, :])          # projected axis start (N, P, 2)
    b = 0.5 * (uv[..., 2, :] + uv[..., 3, :])
    ra = 0.5 * np.linalg.norm(uv[..., 1, :] - uv[..., 0, :], axis=-1)
    rb = 0.5 * np.linalg.norm(uv[..., 3, :] - uv[..., 2, :], axis=-1)
    t = ((np.arange(along) + 0.5) / along).astype(np.float32)
    # Axis points of the occludees' sample rows: (N, W, A, 2) and depths (N, W, A).
    pts = a[:, who, None, :] + t[None, None, :, None] * (b - a)[:, who, None, :]
    dep = d_start[:, who, None] + t[None, None, :] * (d_end - d_start)[:, who, None]
    occ = table[who]                                    # (W, Q)
    real = occ >= 0
    occ = np.where(real, occ, 0)
    oa, ob = a[:, occ], b[:, occ]                       # (N, W, Q, 2)
    seg = ob - oa
    rel = pts[:, :, None, :, :] - oa[:, :, :, None, :]  # (N, W, Q, A, 2)
    length2 = np.maximum(np.sum(seg * seg, axis=-1), 1e-9)[..., None]
    tau = np.clip(np.sum(rel * seg[:, :, :, None, :], axis=-1) / length2, 0.0, 1.0)  # (N, W, Q, A)
    closest = oa[:, :, :, None, :] + tau[..., None] * seg[:, :, :, None, :]
    dist2 = np.sum((pts[:, :, None] - closest) ** 2, axis=-1)
    radius = ra[:, occ][..., None] + tau * (rb - ra)[:, occ][..., None]
    occ_depth = d_start[:, occ][..., None] + tau * (d_end - d_start)[:, occ][..., None]
    behind = (dist2 < radius * radius) & (dep[:, :, None, :] > occ_depth) & real[None, :, :, None]
    hidden[:, who] = behind.any(axis=2)
    return np.repeat(hidden, across, axis=2)


def log_likelihood(parts: tuple[PartShape, ...], segments: BodySegments, prev_segments: BodySegments | None,
                   cameras: list[Camera], features: list[FrameFeatures],
                   occlusion_masks: list[np.ndarray | None] | None = None,
                   config: LikelihoodConfig = LikelihoodConfig()) -> np.ndarray:
    """log p(z_t | s_t) (N,) up to a constant, summed over cameras (eq. 12)."""
    if len(cameras) != len(features):
        raise ValueError(f"likelihood: {len(cameras)} cameras but {len(features)} feature frames")
    masks = list(occlusion_masks) if occlusion_masks else [None] * len(cameras)
    if len(masks) != len(cameras):
        raise ValueError(f"likelihood: {len(cameras)} cameras but {len(masks)} occlusion masks")
    prev = segments if prev_segments is None else prev_segments
    total = np.zeros(len(segments))
    for camera, feats, mask in zip(cameras, features, masks):
        total += camera_log_likelihood(parts, segments, prev, camera, feats, mask, config)
    return total
