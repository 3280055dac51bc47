"""Numpy reference of the image likelihood (test oracle only, not part of the package).

A vectorised numpy implementation of ``awalker_tracker.vision.likelihood``, whose per-state
loops are compiled with numba (same model: see that module's docstring), float32, all N states
at once. ``test_likelihood_kernel.py`` checks the compiled likelihood
against it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from awalker_tracker.model.body import BodySegments, PartShape
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.features import FrameFeatures
from awalker_tracker.vision.flow import student_t_e2, student_t_log_ratio
# the look-up tables are prepared once per frame in Python, not in the kernel under test: shared
from awalker_tracker.vision.likelihood import (LikelihoodConfig, _AppearanceTable, _check_inputs, _FlowTable,
                                               occluder_pairs)


def _project(camera: Camera, points: np.ndarray, component_first: bool = False
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """float32 projection of world points (..., 3) (or (3, ...) if ``component_first``): u, v
    (px; -1e6 behind the camera) and depth (m)."""
    R = camera.rotation.astype(np.float32)
    c = camera.position.astype(np.float32)
    px, py, pz = points if component_first else (points[..., 0], points[..., 1], points[..., 2])
    dx, dy, dz = px - c[0], py - c[1], pz - c[2]
    x = dx * R[0, 0] + dy * R[1, 0] + dz * R[2, 0]
    y = dx * R[0, 1] + dy * R[1, 1] + dz * R[2, 1]
    z = dx * R[0, 2] + dy * R[1, 2] + dz * R[2, 2]
    front = z > 1e-6
    inv = np.float32(1) / np.where(front, z, np.float32(1))
    x *= inv
    y *= inv
    if np.any(camera.distortion):
        x, y = camera._distort(x, y)
    K = camera.K.astype(np.float32)
    far = np.float32(-1e6)
    u = np.where(front, K[0, 0] * x + K[0, 1] * y + K[0, 2], far)
    v = np.where(front, K[1, 1] * y + K[1, 2], far)
    return u, v, z


@dataclass
class _Silhouettes:
    """Projected parts of N states: axis ends (px), half-widths (px), depths (m), all (P, N)."""

    ax: np.ndarray
    ay: np.ndarray
    bx: np.ndarray
    by: np.ndarray
    ha: np.ndarray
    hb: np.ndarray
    da: np.ndarray
    db: np.ndarray

    def take(self, chunk: slice) -> "_Silhouettes":
        """The states in ``chunk`` (views)."""
        return _Silhouettes(*(getattr(self, f)[:, chunk] for f in ("ax", "ay", "bx", "by", "ha", "hb", "da", "db")))


def _silhouettes(parts: tuple[PartShape, ...], segments: BodySegments, camera: Camera,
                 widths: bool = True) -> _Silhouettes:
    """Projected axis ends, half-widths (px) and end depths of every part, (P, N) float32 each."""
    rot = np.asarray(segments.rotation, np.float32)
    origin = np.asarray(segments.origin, np.float32).transpose(2, 1, 0)      # (3, P, N)
    axis = rot[..., :, 2].transpose(2, 1, 0)
    lengths = np.array([p.length for p in parts], np.float32)[:, None]
    end = origin + lengths * axis
    u, v, depth = _project(camera, np.stack([origin, end], axis=-1), component_first=True)   # (P, N, 2)
    da, db = depth[..., 0], depth[..., 1]
    if not widths:
        zero = np.zeros_like(da)
        return _Silhouettes(u[..., 0], v[..., 0], u[..., 1], v[..., 1], zero, zero, da, db)
    r_start = np.array([p.radii_start for p in parts], np.float32)[:, :, None]   # (P, 2, 1)
    r_end = np.array([p.radii_end for p in parts], np.float32)[:, :, None]
    cam = camera.position.astype(np.float32)
    vx, vy, vz = (cam[k] - 0.5 * (origin[k] + end[k]) for k in range(3))    # towards the camera
    ax, ay, az = axis
    lx, ly, lz = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx     # lateral = axis x view
    e0 = rot[..., :, 0].transpose(2, 1, 0)
    e1 = rot[..., :, 1].transpose(2, 1, 0)
    c0 = lx * e0[0] + ly * e0[1] + lz * e0[2]
    c1 = lx * e1[0] + ly * e1[1] + lz * e1[2]
    norm = np.sqrt(c0 * c0 + c1 * c1)            # lateral lies in the e0-e1 plane
    degenerate = norm < 1e-9                     # looking along the axis: any lateral direction
    inv = np.float32(1) / np.where(degenerate, np.float32(1), norm)
    c0 = np.where(degenerate, np.float32(1), c0 * inv)
    c1 = np.where(degenerate, np.float32(0), c1 * inv)
    h0 = np.sqrt((r_start[:, 0] * c0) ** 2 + (r_start[:, 1] * c1) ** 2)
    h1 = np.sqrt((r_end[:, 0] * c0) ** 2 + (r_end[:, 1] * c1) ** 2)
    focal = np.float32(0.5 * (camera.K[0, 0] + camera.K[1, 1]))
    ha = focal * h0 / np.maximum(da, np.float32(1e-6))
    hb = focal * h1 / np.maximum(db, np.float32(1e-6))
    return _Silhouettes(u[..., 0], v[..., 0], u[..., 1], v[..., 1], ha, hb, da, db)


def camera_log_likelihood(parts: tuple[PartShape, ...], segments: BodySegments, prev_segments: BodySegments,
                          camera: Camera, features: FrameFeatures, config: LikelihoodConfig = LikelihoodConfig(),
                          silhouettes: _Silhouettes | None = None,
                          prev_silhouettes: _Silhouettes | None = None) -> np.ndarray:
    """Log-likelihood (N,) of one camera's features (see the module docstring).

    ``silhouettes`` / ``prev_silhouettes``: the poses already projected into this camera
    (``_silhouettes``), if known. The states are processed in chunks of 4096
    so that the per-sample arrays stay in the CPU cache; arrays are laid out (A, P, n) and
    (J, A, P, n) so that sums over the few sample rows and columns add contiguous blocks."""
    _check_inputs(parts, segments, camera, features)
    n = segments.origin.shape[0]
    sil = _silhouettes(parts, segments, camera) if silhouettes is None else silhouettes
    appearance = _AppearanceTable(parts, features)
    flow = _FlowTable(features.flow) if config.flow_weight > 0 else None
    if flow is not None and not flow.any:
        flow = None
    prev = None
    if flow is not None:
        prev = prev_silhouettes if prev_silhouettes is not None else _silhouettes(parts, prev_segments, camera,
                                                                                  widths=False)
    total = np.empty(n)
    step = 4096     # states per chunk (keeps the sample arrays in cache)
    for start in range(0, n, step):
        chunk = slice(start, min(start + step, n))
        total[chunk] = _chunk_log_likelihood(parts, sil.take(chunk), None if prev is None else prev.take(chunk),
                                             appearance, flow, config)
    return total


def _chunk_log_likelihood(parts: tuple[PartShape, ...], sil: "_Silhouettes", prev: "_Silhouettes | None",
                          appearance: _AppearanceTable, flow: _FlowTable | None,
                          config: LikelihoodConfig) -> np.ndarray:
    """Appearance + flow log-likelihood of a chunk of states, (n,) float64."""
    A, J = config.points_along, config.points_across
    t = ((np.arange(A) + 0.5) / A).astype(np.float32)[:, None, None]      # row positions along the axis
    s = (2 * (np.arange(J) + 0.5) / J - 1).astype(np.float32)              # across, in half-widths
    dx, dy = sil.bx - sil.ax, sil.by - sil.ay
    length = np.sqrt(dx * dx + dy * dy)
    long_enough = length > 1e-3
    inv_len = np.float32(1) / np.where(long_enough, length, np.float32(1))
    nx = np.where(long_enough, -dy * inv_len, np.float32(1))              # unit normal of the axis in the image
    ny = np.where(long_enough, dx * inv_len, np.float32(0))
    # Row centres and half-widths (A, P, n).
    cx = sil.ax + t * dx
    cy = sil.ay + t * dy
    half = sil.ha + t * (sil.hb - sil.ha)
    in_front = (sil.da > 1e-6) & (sil.db > 1e-6)
    row_ok = np.broadcast_to(in_front, cx.shape).copy()
    if config.self_occlusion:
        # The occlusion test at every other row (pairs of rows share it): it is the costliest step.
        t_even = t[::2]
        hidden = _hidden_rows(parts, sil, cx[::2], cy[::2], sil.da + t_even * (sil.db - sil.da))
        row_ok &= ~np.repeat(hidden, 2, axis=0)[:A]
    # Eq. 11 weights: each part in front of the camera counts its mean ratio (module docstring) (P, n).
    scale = in_front.astype(np.float32)    # ---- appearance: sample points (J, A, P, n) --------------------------------------------
    tab = appearance
    # Map coordinates (+1 for the zero border) of the row centres and of the across-axis step.
    # Pixel centres are at integer image coordinates (``Camera.project``, ``render``), so map
    # pixel j averages image pixels d j .. d j + d - 1 and spans [d j - 0.5, d j + d - 0.5):
    # floor((u + 0.5) / d). (floor(u / d) read every point half an image pixel up and left.)
    inv_ds = np.float32(tab.inv_ds)
    base_col = (cx + np.float32(0.5)) * inv_ds + np.float32(1)
    base_row = (cy + np.float32(0.5)) * inv_ds + np.float32(1)
    step_col = half * nx * inv_ds
    step_row = half * ny * inv_ds
    flat = np.empty((J,) + cx.shape, np.int32)
    for j in range(J):
        col = np.clip(base_col + s[j] * step_col, 0, tab.w + 1)
        row = np.clip(base_row + s[j] * step_row, 0, tab.h + 1)
        np.multiply(row.astype(np.int32), tab.w + 2, out=flat[j])
        flat[j] += col.astype(np.int32)
        flat[j] += tab.offsets[:, None]
    values = np.take(tab.values, flat)   # take: ~2x faster than fancy indexing here
    row_sums = values[0]
    for j in range(1, J):
        row_sums = row_sums + values[j]
    row_sums *= row_ok
    part_sums = row_sums[0]
    for a in range(1, A):
        part_sums = part_sums + row_sums[a]
    total = config.appearance_weight / (A * J) * np.sum(scale * part_sums, axis=0, dtype=np.float64)
    names = [p.name for p in parts]
    if config.head_top_weight > 0 and "head" in names:
        # the person's foreground just above the head's top (0.75 map pixels out along the image axis)
        # counts against the body, at half the head's end width across (n,)
        h = names.index("head")
        ok = in_front[h] & long_enough[h]
        margin = np.float32(0.75) / (inv_ds * np.where(ok, length[h], np.float32(1)))
        top_col = (sil.bx[h] + margin * dx[h] + np.float32(0.5)) * inv_ds + np.float32(1)
        top_row = (sil.by[h] + margin * dy[h] + np.float32(0.5)) * inv_ds + np.float32(1)
        above = np.zeros(top_col.shape, np.float64)
        for j in range(J):
            col = np.clip(top_col + s[j] * np.float32(0.5) * sil.hb[h] * nx[h] * inv_ds, 0, tab.w + 1)
            row = np.clip(top_row + s[j] * np.float32(0.5) * sil.hb[h] * ny[h] * inv_ds, 0, tab.h + 1)
            at = tab.offsets[h] + row.astype(np.int32) * (tab.w + 2) + col.astype(np.int32)
            above += np.maximum(np.take(tab.values, at), 0)
        total -= np.where(ok, config.appearance_weight * config.head_top_weight / J * above, 0.0)
    # ---- flow at the axis points of every flow_row_step-th row (rows, P, n) ---------------
    if flow is not None and prev is not None:
        pick = slice(None, None, config.flow_row_step)       # flow cells are coarser than the rows
        tp, fx_, fy_, ok = t[pick], cx[pick], cy[pick], row_ok[pick]
        mu = fx_ - (prev.ax + tp * (prev.bx - prev.ax))                    # predicted motion (px/frame)
        mv = fy_ - (prev.ay + tp * (prev.by - prev.ay))
        inv_cell = np.float32(flow.inv_cell)
        fcol = (fx_ + np.float32(0.5)) * inv_cell      # cell k spans [k s - 0.5, k s + s - 0.5) px
        frow = (fy_ + np.float32(0.5)) * inv_cell
        inside = (fcol >= 0) & (fcol < flow.cols) & (frow >= 0) & (frow < flow.rows) & ok
        inside &= (prev.da > 1e-6) & (prev.db > 1e-6)
        # (points behind the camera project to NaN: zeroed before the integer cast, then sent to the dummy cell)
        frow, fcol = np.where(inside, frow, np.float32(0)), np.where(inside, fcol, np.float32(0))
        cell = np.where(inside, frow.astype(np.int32) * flow.cols + fcol.astype(np.int32), flow.valid.size - 1)
        du = flow.fx[cell] - mu
        dv = flow.fy[cell] - mv
        # eq. 9 from vision.flow (its one implementation, tested against scipy in test_flow.py)
        ratio = student_t_log_ratio(student_t_e2(du, dv, flow.i00[cell], flow.i01[cell], flow.i11[cell]),
                                    flow.log0[cell])
        ratio = np.where(flow.valid[cell], ratio, np.float32(0))
        total += config.flow_weight / ratio.shape[0] * np.sum(scale * ratio.sum(axis=0), axis=0, dtype=np.float64)
    return total


def _hidden_rows(parts: tuple[PartShape, ...], sil: _Silhouettes, cx: np.ndarray, cy: np.ndarray,
                 depth: np.ndarray) -> np.ndarray:
    """(A, P, n) True where a row's axis point is hidden by another part (module docstring).

    All candidate (pair, state) combinations are tested at once: those whose image bounding
    boxes meet and whose occludee is not wholly in front of the occluder."""
    hidden = np.zeros(cx.shape, bool)
    occludees, occluders = occluder_pairs(parts)
    if occludees.size == 0:
        return hidden
    hmax = np.maximum(sil.ha, sil.hb)
    x0, x1 = np.fmin(sil.ax, sil.bx) - hmax, np.fmax(sil.ax, sil.bx) + hmax
    y0, y1 = np.fmin(sil.ay, sil.by) - hmax, np.fmax(sil.ay, sil.by) + hmax
    near, far = np.fmin(sil.da, sil.db), np.fmax(sil.da, sil.db)
    I, J = occludees, occluders
    meet = (x0[I] < x1[J]) & (x0[J] < x1[I]) & (y0[I] < y1[J]) & (y0[J] < y1[I]) & (far[I] > near[J])  # (Q, n)
    q, k = np.nonzero(meet)
    if q.size == 0:
        return hidden
    i, j = I[q], J[q]
    # gathers by flat index with np.take (several times faster than 2-D fancy indexing)
    n = cx.shape[-1]
    jk, ik = j * n + k, i * n + k

    def at_occluder(a: np.ndarray) -> np.ndarray:      # a (P, n) -> (M,)
        return np.take(a, jk)

    def at_row(a: np.ndarray) -> np.ndarray:           # a (A, P, n) -> (A, M)
        return np.take(a.reshape(a.shape[0], -1), ik, axis=1)

    ax, ay = at_occluder(sil.ax), at_occluder(sil.ay)
    sx, sy = at_occluder(sil.bx) - ax, at_occluder(sil.by) - ay
    px, py = at_row(cx) - ax, at_row(cy) - ay                                 # (A, M)
    tau = np.clip((px * sx + py * sy) / np.maximum(sx * sx + sy * sy, np.float32(1e-6)), 0, 1)
    ex, ey = px - tau * sx, py - tau * sy
    ha = at_occluder(sil.ha)
    radius = ha + tau * (at_occluder(sil.hb) - ha)
    da = at_occluder(sil.da)
    behind = at_row(depth) > da + tau * (at_occluder(sil.db) - da)
    covered = (ex * ex + ey * ey < radius * radius) & behind
    for row in range(cx.shape[0]):       # set-only writes: repeated (part, state) entries are harmless
        hit = covered[row]
        hidden[row, i[hit], k[hit]] = True
    return hidden


def reference_log_likelihood(parts: tuple[PartShape, ...], segments: BodySegments,
                             prev_segments: BodySegments | None, cameras: list[Camera],
                             features: list[FrameFeatures], config: LikelihoodConfig = LikelihoodConfig()) -> np.ndarray:
    """log p(z_t | s_t) (N,) summed over cameras (eq. 12), computed with numpy."""
    prev = segments if prev_segments is None else prev_segments
    total = np.zeros(len(segments))
    for camera, feats in zip(cameras, features):
        sil = _silhouettes(parts, segments, camera)
        prev_sil = sil if prev is segments else None
        total += camera_log_likelihood(parts, segments, prev, camera, feats, config, sil, prev_sil)
    return total
